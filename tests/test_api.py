import subprocess
import sys


def test_every_public_name_resolves():
    import schedsyn

    for name in schedsyn.__all__:
        assert getattr(schedsyn, name) is not None, name


def test_import_is_light():
    """``import schedsyn`` loads neither matplotlib nor cvxpy (the planner is lazy)."""
    code = "import sys, schedsyn; print('matplotlib' in sys.modules, 'cvxpy' in sys.modules)"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.split() == ["False", "False"]
