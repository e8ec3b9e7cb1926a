"""A recording by its kind's name: `"highd:PATH"` or `"ngsim:PATH"`, read by that kind's reader."""

from __future__ import annotations

from diffsense.runtime import InputError
from diffsense.scene._datatypes import Scene
from diffsense.scene._highd import load_highd
from diffsense.scene._ngsim import load_ngsim


def load_recorded(spec: str, **options) -> list[Scene]:
    """Scenes from `"highd:PATH"` (a highD NN_tracks.csv) or `"ngsim:PATH"` (an NGSIM trajectory CSV).

    `options` (duration_s, crossing_at_s, hold_s, dtype) go to `load_highd` / `load_ngsim`.
    """
    kind, sep, path = str(spec).partition(":")
    loaders = {"highd": load_highd, "ngsim": load_ngsim}
    if not sep or kind.lower() not in loaders or not path:
        raise InputError(f"recorded scenes are named 'highd:PATH' or 'ngsim:PATH', got {spec!r}")
    return loaders[kind.lower()](path, **options)
