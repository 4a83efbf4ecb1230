"""Property-based: `simulate` with random values for every configuration key.

Whatever the values (non-finite, huge, tiny, wrong types, nested), a run ends
with exit 0 and finite outputs, or exit 2 and one line on stderr: never a
traceback, never a folder left behind. Driven in-process through the same
`--set KEY=VALUE` a user types, a few hundred examples per run of the suite,
with hypothesis's fixed (derandomized) search so CI sees the same examples.
"""

import json
import math
import shutil

import pytest
import yaml
from conftest import cli
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from cmosnoise import load_config


def _leaf_keys(data, prefix=""):
    if isinstance(data, dict):
        for k, v in data.items():
            yield from _leaf_keys(v, f"{prefix}{k}.")
    elif isinstance(data, list) and data and isinstance(data[0], (dict, list)):
        for i, v in enumerate(data):
            yield from _leaf_keys(v, f"{prefix}{i}.")
    yield prefix.rstrip(".")


KEYS = sorted({k for k in _leaf_keys(load_config().model_dump(mode="json")) if k})
#: keys whose size sets the run's cost: fuzzed in type and sign, not in magnitude (a million frames is valid, and slow)
COST = {"run.frames", "processing.dark_frames", "processing.video_fps"}

EDGES = [0, -1, 1, 2, 0.5, 1e-300, 1e300, 1e30, -1e30, 2**63, float("inf"), float("-inf"), float("nan"), "", "abc",
         None, True, False, [], {}, {"a": 1}, [1, 2], [[1, 2, 3]] * 3, "1e5", "flat:2", "flat:-1", "photo", "steps:0"]
VALUES = st.one_of(
    st.sampled_from(EDGES),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**12), max_value=10**12),
    st.text(max_size=6),
    st.lists(st.floats(allow_nan=False, min_value=-1e6, max_value=1e6), max_size=4),
    st.dictionaries(st.sampled_from(["a", "mean_e_per_s", "enabled", "R"]), st.integers(-5, 5), max_size=2),
)
COST_VALUES = st.sampled_from([0, 1, 2, -1, 1.5, "x", None, float("inf"), float("nan"), [], {"a": 1}, True])


DEFAULTS = load_config().model_dump(mode="json")


def _default(key):
    node = DEFAULTS
    for part in key.split("."):
        node = node[int(part)] if isinstance(node, list) else node[part]
    return node


def _plausible(key):
    """Values near the default: a working run is as much the point as a refused one."""
    d = _default(key)
    if isinstance(d, bool):
        return st.booleans()
    if isinstance(d, (int, float)):
        if key in COST:
            return st.integers(0, 3)
        kind = st.integers(0, max(2 * int(d), 4)) if isinstance(d, int) else st.floats(0, 4).map(lambda f: f * d if d else f)
        return kind
    if d is None:
        return st.one_of(st.none(), st.floats(0, 100))
    return st.just(d)


def _assignment(key):
    return st.tuples(st.just(key), st.one_of(_plausible(key), _plausible(key), COST_VALUES if key in COST else VALUES))


ASSIGNMENTS = st.lists(st.sampled_from(KEYS).flatmap(_assignment), min_size=1, max_size=4)


def _yaml(value) -> str:
    return yaml.safe_dump(value, default_flow_style=True, width=10**6).strip().removesuffix("\n...").strip()


def _no_constants(name):
    raise ValueError(f"summary.json holds {name}")


@settings(max_examples=300, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(assignments=ASSIGNMENTS)
@example(assignments=[("optics.angle_relative_qe", "\x00")])  # a NUL in a table's name: os.open's ValueError, once
@pytest.mark.slow
def test_any_configuration_value_gives_output_or_one_line(tmp_path_factory, assignments):
    base = tmp_path_factory.mktemp("fuzz")
    out = base / "run"
    args = ["simulate", "--no-progress", "--set", "sensor.width=32", "--set", "sensor.height=24", "--out", out]
    for key, value in assignments:
        args += ["--set", f"{key}={_yaml(value)}"]
    try:
        r = cli(*args)
        event(f"exit {r.returncode}")
        assert "Traceback" not in r.stderr, (assignments, r.stderr)
        assert r.returncode in (0, 2), (assignments, r.returncode, r.stderr)
        if r.returncode == 2:
            lines = r.stderr.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith(("cmosnoise: error:", "Usage", "Error")), (assignments, r.stderr)
            assert not out.exists(), assignments
        else:
            summary = json.loads((out / "summary.json").read_text(), parse_constant=_no_constants)
            assert (out / "raw.tiff").exists() and (out / "config.yaml").exists()
            assert math.isfinite(summary["signal"]["mean_e"])
            assert "Warning" not in r.stderr and "Traceback" not in r.stderr, (assignments, r.stderr)
        assert [p.name for p in base.iterdir() if p.name.startswith(".cmosnoise-")] == [], assignments
    finally:
        shutil.rmtree(base, ignore_errors=True)
