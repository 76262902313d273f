import os

import matplotlib
import pytest

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture
def rng():
    import numpy as np

    return np.random.default_rng(12345)


#: Modules whose tests share an expensive module fixture (a split, advice, a graded
#: search, ...) or a module-level memo (test_replan's planner answers, ``PLANNED``, which
#: two of its ~30 s tests ask alike): under pytest-xdist each runs whole on one worker, so
#: the work is done once. (pytest-xdist's own ``--dist loadgroup`` marks stopped
#: grouping with pytest 9.2's structured node ids, pytest-xdist issue #1386: the tests
#: were spread as if unmarked.) Every other test is its own unit, as with ``--dist load``.
WHOLE_MODULES = frozenset(
    f"tests/test_{name}.py"
    for name in ("advise", "graded_effort", "informative", "ramps", "reach", "replan", "split")
)

#: Modules that read another whole module's memo run in that module's unit, after it:
#: test_replan_choice asks test_replan's ``PLANNED`` the requests test_replan asked (its
#: step-limit test took 0.8 s after test_replan on the same worker, 25 s on the other).
SAME_UNIT_AS = {"tests/test_replan_choice.py": "tests/test_replan.py"}


@pytest.hookimpl(optionalhook=True)  # a plain pytest (no xdist) does not know the hook
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadgroup`` (scripts/test.sh): the modules of :data:`WHOLE_MODULES` as one
    unit each (with those of :data:`SAME_UNIT_AS` in theirs), every other test alone; the
    units in order of size (the whole modules first), pytest-xdist's load-scope
    scheduling. Other ``--dist`` modes: xdist's own."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class WholeModules(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            module = SAME_UNIT_AS.get(module, module)
            return module if module in WHOLE_MODULES else nodeid

    return WholeModules(config, log)
