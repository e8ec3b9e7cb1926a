"""What every command-line entry point shares: the exit-code contract and JAX start-up.

Only CLI modules import this. `run(main)` calls `main()` and turns an `InputError` into one line
on stderr and exit code 2 (never a traceback); Ctrl-C exits with 130.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from pathlib import Path

from diffsense.errors import InputError


def run(main: Callable[[], int | None]) -> None:
    """Run a CLI `main` under the project's error contract and exit with its code."""
    try:
        code = main()
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    sys.exit(code or 0)


def setup_jax(float64: bool = True, compilation_cache: bool = True) -> None:
    """Configure JAX before the first computation: precision and the persistent compile cache.

    The cache lives in the user's cache directory (XDG_CACHE_HOME or ~/.cache)/diffsense/jax, so
    a second run of a command skips most compilation.
    """
    import jax

    jax.config.update("jax_enable_x64", float64)
    if compilation_cache and os.environ.get("DIFFSENSE_NO_CACHE") != "1":
        base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
        cache_dir = base / "diffsense" / "jax"
        try:
            cache_dir.mkdir(parents=True, exist_ok=True)
            jax.config.update("jax_compilation_cache_dir", str(cache_dir))
            jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
        except OSError:
            pass  # a read-only home only costs speed
