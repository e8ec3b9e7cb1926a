"""A recording by its kind's name: `"highd:PATH"` or `"ngsim:PATH"`, read by that kind's reader."""

from __future__ import annotations

from diffsense.runtime import InputError
from diffsense.scene._datatypes import Scene
from diffsense.scene._highd import read_highd
from diffsense.scene._ngsim import read_ngsim
from diffsense.scene._recorded import check_window, recorded_scenes
from diffsense.scene._recorded_types import DEFAULT_HOLD_S, DEFAULT_WINDOW_S, RecordedCut

_READERS = {"highd": read_highd, "ngsim": read_ngsim}


def cut_recorded(spec: str, *, window_s: float = DEFAULT_WINDOW_S, crossing_at_s: float | None = None,
                 hold_s: float = DEFAULT_HOLD_S, dtype=None) -> RecordedCut:
    """`"highd:PATH"` (a highD NN_tracks.csv) or `"ngsim:PATH"` (an NGSIM trajectory CSV) read and
    cut into scenes (`recorded_scenes`: the windows, and a summary of what was kept). Host arrays
    only: nothing here starts the JAX backend."""
    kind, sep, path = str(spec).partition(":")
    if not sep or kind.lower() not in _READERS or not path:
        raise InputError(f"recorded scenes are named 'highd:PATH' or 'ngsim:PATH', got {spec!r}")
    check_window(window_s, crossing_at_s, hold_s)  # before reading a large file
    options = {} if dtype is None else {"dtype": dtype}
    return recorded_scenes(_READERS[kind.lower()](path), window_s=window_s, crossing_at_s=crossing_at_s,
                           hold_s=hold_s, **options)


def load_recorded(spec: str, **options) -> list[Scene]:
    """The scenes of `cut_recorded(spec, **options)` (window_s, crossing_at_s, hold_s, dtype)."""
    return list(cut_recorded(spec, **options).scenes)
