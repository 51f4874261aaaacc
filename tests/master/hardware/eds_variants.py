"""EDS variants for the CAN tests: the packaged EDS with objects taken out, sections replaced
or added (PDOs with static mappings), written to a test's temporary directory."""

from __future__ import annotations

import re
from pathlib import Path

from haptic.master.hardware.drive_device import packaged_eds_path

_HEADER = re.compile(r"^\[([^\]]+)\]\s*$", re.MULTILINE)


def packaged() -> str:
    """The packaged EDS's text."""
    return packaged_eds_path().read_text()


def sections(text: str) -> list[tuple[str, str]]:
    """The text's sections in order: (name, the whole section's text)."""
    starts = [(m.group(1), m.start()) for m in _HEADER.finditer(text)]
    ends = [start for _, start in starts[1:]] + [len(text)]
    return [(name, text[start:end]) for (name, start), end in zip(starts, ends, strict=True)]


def without(text: str, *indices: int) -> str:
    """``text`` without the objects ``indices`` (their sections and sub-index sections)."""
    names = {f"{index:04X}" for index in indices}
    head = text[:_HEADER.search(text).start()]
    return head + "".join(body for name, body in sections(text)
                          if name.upper().split("SUB")[0] not in names)


def without_sections(text: str, *names: str) -> str:
    """``text`` without the sections ``names`` (e.g. ``1400sub5``), any case."""
    drop = {name.upper() for name in names}
    head = text[:_HEADER.search(text).start()]
    return head + "".join(body for name, body in sections(text) if name.upper() not in drop)


def entry_set(text: str, section: str, key: str, value: str) -> str:
    """``text`` with ``key=value`` in ``section`` (e.g. ``6502``, ``1600sub1``)."""
    out = []
    for name, body in sections(text):
        if name.upper() == section.upper():
            body, count = re.subn(rf"^{key}=.*$", f"{key}={value}", body, flags=re.MULTILINE)
            assert count == 1, (section, key)
        out.append(body)
    return text[:_HEADER.search(text).start()] + "".join(out)


def variable(index: int, sub: int | None, name: str, data_type: int, access: str,
             value: str) -> str:
    """One variable's section."""
    section = f"{index:04X}" + (f"sub{sub:X}" if sub is not None else "")
    return (f"[{section}]\nParameterName={name}\nObjectType=0x7\nDataType=0x{data_type:04X}\n"
            f"AccessType={access}\nDefaultValue={value}\nPDOMapping=0\n\n")


def pdo(comm: int, cob_id: str, transmission: int, entries: tuple[int, ...],
        mapping_access: str = "ro", comm_access: str = "rw", deadline: bool = True) -> str:
    """A PDO's communication object ``comm`` (COB-ID, transmission type, the RPDO deadline
    or event timer) and its mapping ``comm`` + 0x200 with ``entries`` (index << 16 |
    subindex << 8 | bits)."""
    mapping = comm + 0x200
    text = (f"[{comm:04X}]\nParameterName=PDO communication parameter\nObjectType=0x9\n"
            f"SubNumber={4 if deadline else 3}\n\n"
            + variable(comm, 0, "Highest sub-index supported", 5, "const",
                       "5" if deadline else "2")
            + variable(comm, 1, "COB-ID", 7, comm_access, cob_id)
            + variable(comm, 2, "Transmission type", 5, comm_access, str(transmission)))
    if deadline:
        text += variable(comm, 5, "Event timer", 6, "rw", "0")
    text += (f"[{mapping:04X}]\nParameterName=PDO mapping parameter\nObjectType=0x9\n"
             f"SubNumber={len(entries) + 1}\n\n"
             + variable(mapping, 0, "Number of mapped objects", 5, mapping_access,
                        str(len(entries))))
    for sub, entry in enumerate(entries, start=1):
        text += variable(mapping, sub, f"Application object {sub}", 7, mapping_access,
                         f"0x{entry:08X}")
    return text


def written(tmp_path: Path, name: str, text: str) -> Path:
    """``text`` as the file ``name`` in ``tmp_path``."""
    path = tmp_path / name
    path.write_text(text)
    return path
