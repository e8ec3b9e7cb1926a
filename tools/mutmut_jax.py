"""pytest plugin for mutation runs (setup.cfg [mutmut] loads it with `-p tools.mutmut_jax`).

mutmut first records which tests reach which function ("stats"), by the calls its trampolines
see. A jitted function runs its Python only while it is traced: a test that hits a function
another test already compiled would not be recorded as reaching it, and mutants of that function
would later skip the test. So while the stats are recorded, every test starts with jax's caches
cleared. Mutant runs are unaffected (each is a fresh process whose traces include the mutant).
"""

from __future__ import annotations

import os

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    del item
    if os.environ.get("MUTANT_UNDER_TEST") == "stats":
        import jax

        jax.clear_caches()
