"""mkdocs hooks of the documentation build (`hooks:` in mkdocs.yml).

The docstrings write units and array shapes in brackets: `[m]`, `[deg]`, `[-]`, `[1/m]`, `[N, T]`.
Where one follows another bracketed text, as in "in [0, 1] [-]", Markdown reads the pair as a
reference-style link `[text] [id]`, and mkdocs-autorefs warns that the cross-reference target `-`
does not exist. That warning fails `mkdocs build --strict`. A unit or a shape is never a
cross-reference, so this hook drops exactly those warnings: raised from a docstring, with a unit
or a shape as the target. Every other unresolved cross-reference still fails the build.
"""

from __future__ import annotations

import logging
import re

# "Could not find cross-reference target 'm'", raised from "from /path/file.py:91: (origin)"
_UNRESOLVED = re.compile(r"from \S+\.py:\d+: .*Could not find cross-reference target '(?P<target>[^']*)'")
# The units the docstrings write in brackets.
_UNITS = frozenset(
    "- % m s ms deg rad dB dBi dBm dBsm px Hz kHz GHz ft km 1/m 1/s m/s m/s2 m/s^2 m^2 "
    "px/rad m/deg veh/km".split()
)
# An array shape: capital dimension names, sizes, commas, "..." and "*", e.g. "N", "T, V", "*T".
_SHAPE = re.compile(r"^[A-Z0-9*., ]+$")


class _UnitRefFilter(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        m = _UNRESOLVED.search(record.getMessage())
        if m is None:
            return True
        target = m.group("target")
        return not (target in _UNITS or _SHAPE.match(target))


def on_config(config):
    # A filter acts only on the logger it is attached to, not on its children: attach it to every
    # logger of the autorefs plugin (loaded with the config, before this hook runs).
    unit_filter = _UnitRefFilter()
    for name in list(logging.root.manager.loggerDict):
        if name.startswith("mkdocs.plugins.mkdocs_autorefs"):
            logging.getLogger(name).addFilter(unit_filter)
    return config
