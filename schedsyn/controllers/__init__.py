"""Chamber-controller programme formats: one module per controller family.

Each codec turns the parts of a quantised programme (see :mod:`schedsyn.export`) into
the text of an export file and reads such a file back, strictly: every limit of the
controller (steps per programme, programme numbers, time and temperature resolution,
the chain between programmes) is checked on reading, so a file edited by hand is
checked too.

============  ==========================  ============================================
exporter      controller                  file
============  ==========================  ============================================
espec-p300    ESPEC P-300                 JSON: ``set_program(N, dict)`` dictionaries
espec-scp220  ESPEC SCP-220               same shape, 20 programmes
watlow-f4t    Watlow F4T                  JSON: ``set_program(N, dict)`` dictionaries
binder-mb     Binder MB1 / MB2            CSV segment table
csv           any (typed in by hand)      schedsyn step table
============  ==========================  ============================================

The dictionaries follow ESPEC North America's ChamberConnectLibrary
(``chamberconnectlibrary/p300.py`` and ``watlowf4t.py``), whose published PyPI release
is Python 2 only: schedsyn emits its dictionaries and does not depend on it. The Binder
segment table follows ``binder.py`` of auger-prime-sde/ess.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from ..export import ControllerSpec, Decoded, ExportSettings
from ..params import Limits
from ..programme import Programme


class Codec(Protocol):
    """Encode the parts of a programme for one controller, and read them back."""

    def encode(
        self,
        parts: Sequence[Programme],
        numbers: Sequence[int],
        settings: ExportSettings,
        limits: Limits,
        header: Mapping[str, Any],
    ) -> str: ...

    def decode(self, text: str, source: str, spec: ControllerSpec) -> Decoded: ...

    def notes(
        self, parts: Sequence[Programme], numbers: Sequence[int], settings: ExportSettings
    ) -> list[str]: ...


def _registry() -> tuple[dict[str, ControllerSpec], dict[str, Codec]]:
    from . import binder, espec, generic, watlow

    specs = {
        s.key: s for s in (espec.P300, espec.SCP220, watlow.F4T, binder.BINDER_MB, generic.CSV)
    }
    codecs: dict[str, Codec] = {
        "espec-p300": espec.EspecCodec(),
        "espec-scp220": espec.EspecCodec(),
        "watlow-f4t": watlow.F4TCodec(),
        "binder-mb": binder.BinderCodec(),
        "csv": generic.CsvCodec(),
    }
    return specs, codecs


SPECS, CODECS = _registry()

__all__ = ["CODECS", "SPECS", "Codec"]
