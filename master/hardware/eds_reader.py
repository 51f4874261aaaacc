"""A drive's EDS or DCF (CiA 306) read with canopen's importer, and the gaps it leaves filled.

``canopen.import_od`` parses the file: the objects, their access types and PDO mapping flags,
``DefaultValue`` and, in a DCF, ``ParameterValue`` (canopen's ``LocalNode`` serves the latter
over the former), ``$NODEID+0x180`` and ``0x180+$NODEID``. :func:`read_dictionary` adds what
it does not do:

- a ``$NODEID`` formula with more than one constant (``0x80000000+$NODEID+0x180``), which
  canopen leaves without a value, is summed (:func:`node_formula`);
- an empty entry in ``[DeviceInfo]`` or ``[DeviceComissioning]`` (``VendorNumber=``, as
  CANopenNode's editor writes them), which canopen cannot parse, is read as absent;
- a DCF's ``[DeviceComissioning] NodeID`` must be the node the file is used for: a DCF holds
  one node's values, so another node's is refused (an EDS's commissioning section, which
  CiA 306 does not define, is ignored).

:func:`file_value` is the value the file gives an object: the DCF's ``ParameterValue`` (what
this node is configured to) over the ``DefaultValue``.
"""

from __future__ import annotations

import io
import re
from pathlib import Path
from typing import Any

import canopen
from canopen import objectdictionary as od

#: The sections whose empty entries are dropped before canopen reads the file.
_INFO_SECTIONS = ("deviceinfo", "devicecomissioning")
_SECTION = re.compile(r"^\s*\[([^\]]+)\]")
_ENTRY = re.compile(r"^\s*([^=;\s]+)\s*=\s*(.*?)\s*(;.*)?$")


def node_formula(text: str, node_id: int) -> int:
    """The value of a CiA 306 ``$NODEID`` formula (``$NODEID+0x180``, ``0x180+$NODEID``,
    ``0x80000000+$NODEID+0x180``; any case, any spaces) for ``node_id``; ``ValueError`` for
    anything else."""
    terms = text.replace(" ", "").upper().split("+")
    if terms.count("$NODEID") != 1 or not all(terms):
        raise ValueError(f"not a $NODEID formula: {text!r}")
    return sum(node_id if term == "$NODEID" else int(term, 0) for term in terms)


def file_value(variable: od.ODVariable) -> Any:
    """The value the EDS/DCF gives ``variable``: ``ParameterValue`` over ``DefaultValue``;
    ``None`` when it gives neither."""
    return variable.value if variable.value is not None else variable.default


def variables(dictionary: od.ObjectDictionary) -> list[od.ODVariable]:
    """Every variable of ``dictionary``: plain ones and the members of records and arrays."""
    found: list[od.ODVariable] = []
    for entry in dictionary.values():
        if isinstance(entry, od.ODVariable):
            found.append(entry)
        else:
            found.extend(entry.values())
    return found


def read_dictionary(path: str | Path, node_id: int) -> od.ObjectDictionary:
    """The object dictionary of the EDS or DCF at ``path`` for ``node_id`` (see the module
    docstring); ``ValueError`` for a DCF of another node or a file canopen cannot read,
    ``OSError`` when it cannot be opened."""
    path = Path(path)
    text, commissioned_node = _without_empty_entries(
        path.read_text(encoding="utf-8", errors="replace"))
    if path.suffix.lower() == ".dcf" and commissioned_node not in (None, node_id):
        raise ValueError(f"it is the DCF of node {commissioned_node} ([DeviceComissioning] "
                         f"NodeID), not of node {node_id}")
    stream = io.StringIO(text)
    stream.name = str(path)  # canopen picks its reader by the name's suffix
    dictionary = canopen.import_od(stream, node_id)
    _resolve_node_formulas(dictionary, node_id)
    return dictionary


def _without_empty_entries(text: str) -> tuple[str, int | None]:
    """``text`` without the empty entries of its device sections, and the DCF's node id
    (``[DeviceComissioning] NodeID``; ``None`` when it gives none)."""
    kept: list[str] = []
    section = ""
    node: int | None = None
    for line in text.splitlines():
        header = _SECTION.match(line)
        if header:
            section = header.group(1).strip().lower()
        elif section in _INFO_SECTIONS and (entry := _ENTRY.match(line)):
            key, value = entry.group(1), entry.group(2)
            if not value:
                continue
            if section == "devicecomissioning" and key.lower() == "nodeid":
                try:
                    node = int(value, 0)
                except ValueError:
                    raise ValueError(f"[DeviceComissioning] NodeID {value!r} is not a "
                                     "number") from None
        kept.append(line)
    return "\n".join(kept) + "\n", node


def _resolve_node_formulas(dictionary: od.ObjectDictionary, node_id: int) -> None:
    """Give the variables whose ``$NODEID`` formula canopen could not evaluate their value."""
    for variable in variables(dictionary):
        for raw_name, name in (("default_raw", "default"), ("value_raw", "value")):
            raw = getattr(variable, raw_name, None)
            if (isinstance(raw, str) and "$NODEID" in raw.upper()
                    and getattr(variable, name) is None):
                try:
                    setattr(variable, name, node_formula(raw, node_id))
                except ValueError:
                    pass  # not a formula of CiA 306: the object has no value from the file
