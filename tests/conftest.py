import os

import matplotlib
import pytest

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture
def rng():
    import numpy as np

    return np.random.default_rng(12345)


# ---------------------------------------------------------------------------------------
# xdist: tests that share a module-scoped fixture run on one worker
# ---------------------------------------------------------------------------------------
# With plain ``--dist load`` a module's tests are spread over both workers and each worker
# makes the module's fixtures again: test_split's split run (over a minute) was made twice.
# ``--dist loadgroup`` with ``xdist_group`` marks would keep them together, but it no longer
# groups under pytest 9 (it renames the test ids, which pytest 9 ignores: pytest-xdist
# issue 1386). So each worker writes down, as it collects, which tests use a module- or
# session-scoped fixture of their own module, and the controller schedules each such
# module's tests as one unit (the other tests are balanced one by one, as with ``load``).
_GROUPS_ENV = "SCHEDSYN_TEST_GROUPS_DIR"


def pytest_configure(config):
    if not hasattr(config, "workerinput") and config.getoption("dist", "no") == "load":
        import tempfile

        os.environ[_GROUPS_ENV] = tempfile.mkdtemp(prefix="schedsyn-test-groups-")


def pytest_unconfigure(config):
    if not hasattr(config, "workerinput") and _GROUPS_ENV in os.environ:
        import shutil

        shutil.rmtree(os.environ.pop(_GROUPS_ENV), ignore_errors=True)


def pytest_collection_modifyitems(config, items):
    folder = os.environ.get(_GROUPS_ENV)
    worker = getattr(config, "workerinput", {}).get("workerid")
    if not folder or worker is None:
        return
    import json

    groups = {}
    for item in items:
        module = getattr(item, "module", None)
        info = getattr(item, "_fixtureinfo", None)
        if module is None or info is None:
            continue
        if any(
            d.scope in ("module", "session")
            and getattr(d.func, "__module__", None) == module.__name__
            for defs in info.name2fixturedefs.values()
            for d in defs
        ):
            groups[item.nodeid] = item.nodeid.split("::", 1)[0]
    tmp = os.path.join(folder, f".{worker}.json")
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(groups, f)
    os.replace(tmp, os.path.join(folder, f"{worker}.json"))


def pytest_xdist_make_scheduler(config, log):
    folder = os.environ.get(_GROUPS_ENV)
    if not folder or config.getoption("dist") != "load":
        return None
    import glob
    import json

    try:
        from xdist.scheduler import LoadScopeScheduling
    except ImportError:  # another pytest-xdist: its own default scheduling
        return None

    class SharedFixtureScheduling(LoadScopeScheduling):
        """``load``, but the tests sharing a module fixture are one unit of work (the
        units with most tests first, as xdist's loadscope does)."""

        _groups: dict[str, str] | None = None

        def _split_scope(self, nodeid: str) -> str:
            if self._groups is None:
                self._groups = {}
                for path in glob.glob(os.path.join(folder, "gw*.json")):
                    with open(path, encoding="utf-8") as f:
                        self._groups.update(json.load(f))
            return self._groups.get(nodeid, nodeid)

    return SharedFixtureScheduling(config, log)
