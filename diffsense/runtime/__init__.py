"""The machinery every stage shares, beneath them all: nothing here knows a sensor or a scene.

    raise InputError("...")                 # bad user input: one line, exit 2 at the CLI
    with atomic_open(path) as f: ...         # a file appears whole or not at all
    out = call(fn, *args)                    # one compiled program, kept on disk across runs
    with CompileClock() as clock: ...        # compile and run time of the programs in a block
    u = uniform(key, shape)                  # random draws laid out the same whatever the shape
    to_host(tree)                            # multi-host: the whole value on every process
"""

from diffsense.runtime._distributed import initialize, is_writer, to_host
from diffsense.runtime._errors import InputError, finite_number
from diffsense.runtime._executables import call, keep_in
from diffsense.runtime._io import (
    abandon_temporaries,
    atomic_open,
    check_writable,
    json_ready,
    output_set,
    published_files,
    register_temporary,
    release_temporary,
    save_figure,
    write_bytes,
    write_json,
)
from diffsense.runtime._random import normal, uniform
from diffsense.runtime._read import read_text_file
from diffsense.runtime._timing import CompileClock
from diffsense.runtime._version import __version__

__all__ = [
    "CompileClock", "InputError", "__version__", "abandon_temporaries", "atomic_open", "call",
    "check_writable", "finite_number", "initialize", "is_writer", "json_ready", "keep_in", "normal", "output_set", "published_files", "read_text_file",
    "register_temporary", "release_temporary", "save_figure", "to_host", "uniform", "write_bytes",
    "write_json",
]
