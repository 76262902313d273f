"""CSV dialect detection: separator and decimal mark from a file's first lines."""

import pytest

from schedsyn.csvdialect import CsvDialect, detect_csv_dialect


@pytest.mark.parametrize(
    ("head", "expected"),
    [
        ("time_s,t_int_c\n0,20.5\n10,20.75\n", (",", ".")),
        ("time_s;t_int_c\n0;20,5\n10;20,75\n", (";", ",")),  # European spreadsheet
        ("time_s;t_int_c\n0;20.5\n10;20.75\n", (";", ".")),  # semicolons, decimal points
        ("time_s\tt_int_c\n0\t-20,5\n10\t-20,75\n", ("\t", ",")),
        ("time_s\tt_int_c\n0\t20.5\n", ("\t", ".")),
        ("\ufefftime_s;t_int_c\r\n0;1,5e-1\r\n", (";", ",")),  # BOM, CRLF, exponent
        ("time_s,t_int_c\n0,20\n10,21\n", (",", ".")),  # integers only
        ("time_s;t_int_c\n0;20\n10;21\n", (";", ".")),
        ("# exported by the chamber\n\ntime_s;t_int_c\n0;20,5\n", (";", ",")),
        ("t_int_c\n20.5\n", (",", ".")),  # one column
        ("", (",", ".")),
        # a head cut in the middle of a line: the partial line is ignored
        ("time_s;t_int_c\n0;20,5\n10;20,7", (";", ",")),
        # a quoted comma in a comma file is a text field, not a decimal mark
        ('time_s,t_int_c,note\n0,20.5,"a, b"\n', (",", ".")),
        # a stray ragged line among many does not change the answer
        ("a;b\n" + "1;2,5\n" * 20 + "1;2,5;\n", (";", ",")),
    ],
)
def test_dialects(head, expected):
    d = detect_csv_dialect(head)
    assert isinstance(d, CsvDialect) and tuple(d) == expected


def test_decimal_commas_in_a_comma_file_are_named():
    with pytest.raises(ValueError, match=r"decimal commas in a comma-separated.*semicolon"):
        detect_csv_dialect("time_s,t_int_c\n0,20,5\n10,20,75\n")


def test_an_unterminated_quote_is_named():
    """Red team: `10,"20.1` swallowed the lines after it and was told "decimal commas in
    a comma-separated file"."""
    with pytest.raises(ValueError, match=r"data line 2 \('10,\"20\.1'\) has an unterminated"):
        detect_csv_dialect('time_s,t_int_c\n0,20\n10,"20.1\n20,20,5,6\n30\n')
    assert detect_csv_dialect('time_s,note\n0,"say ""hi"""\n').separator == ","


def test_mixed_decimal_marks_are_named():
    with pytest.raises(ValueError, match=r"mixes decimal commas \('20,5'\) and decimal points"):
        detect_csv_dialect("time_s;t_int_c;tk_set_c\n0;20,5;19.5\n")


def test_describe():
    assert CsvDialect(";", ",").describe() == "semicolon-separated, decimal comma"
    assert CsvDialect(",", ".").describe() == "comma-separated, decimal point"
