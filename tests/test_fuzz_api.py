"""The Python API under fuzzing (#59), beside the command line's (test_fuzz.py): arrays of wrong shapes, dtypes
and values, and numbers of every kind, into Sensor, expose, frame and frames, Processor and the metrics. Every
call either works or raises CmosnoiseError (one line, naming the argument): no other exception, no crash.
"""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from cmosnoise import Sensor
from cmosnoise.analysis import scoring
from cmosnoise.errors import CmosnoiseError
from cmosnoise.isp.process import Processor

ROWS, COLS = 24, 32
SENSOR = Sensor({"sensor": {"width": COLS, "height": ROWS}}, seed=1)
SHOT = SENSOR.expose("flat:0.5")
PROCESSOR = Processor(SENSOR.config.processing, SENSOR.raw_info())

DTYPES = st.sampled_from([np.uint8, np.uint16, np.int32, np.int64, np.float32, np.float64, np.complex128, np.bool_,
                          np.dtype("U2"), np.dtype("O")])
SHAPES = st.sampled_from([(), (0,), (ROWS,), (ROWS, COLS), (ROWS, COLS, 1), (ROWS, COLS, 3), (ROWS, COLS, 4),
                          (COLS, ROWS), (2, ROWS, COLS), (1, 1), (ROWS + 1, COLS)])
NUMBERS = st.one_of(st.integers(-2**70, 2**70), st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
                    st.none(), st.text(max_size=4), st.just(np.float32(np.nan)), st.just(np.int64(-1)),
                    st.just(1 + 2j), st.lists(st.integers(-3, 3), max_size=5))


@st.composite
def arrays(draw):
    dtype, shape = np.dtype(draw(DTYPES)), draw(SHAPES)
    if dtype.kind in "UO":
        return np.full(shape, "x", dtype=dtype)
    if dtype.kind == "b":
        return draw(hnp.arrays(dtype, shape))
    fill = draw(st.sampled_from([0, 1, 300, -5, np.nan, np.inf, 1e300]))
    with np.errstate(all="ignore"):
        a = np.full(shape, fill).astype(dtype) if dtype.kind != "c" else np.full(shape, fill + 1j)
    if a.size and draw(st.booleans()):
        a.flat[draw(st.integers(0, a.size - 1))] = draw(st.sampled_from([0, 7])) if dtype.kind in "ui" else np.nan
    return a


def _ok_or_one_line(call):
    try:
        call()
    except CmosnoiseError as exc:
        assert "\n" not in str(exc).strip() and str(exc).strip(), repr(exc)


FUZZ = settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))


@FUZZ
@given(a=arrays())
def test_any_array_into_expose_processor_and_metrics_is_taken_or_refused_in_one_line(a):
    _ok_or_one_line(lambda: SENSOR.expose(a))
    _ok_or_one_line(lambda: PROCESSOR.render(a))
    _ok_or_one_line(lambda: PROCESSOR.render(a, half=True))
    truth = np.full((ROWS, COLS), 300.0)
    _ok_or_one_line(lambda: scoring.image_scores(a, truth, 64.0, 4095.0))
    _ok_or_one_line(lambda: scoring.image_scores(truth, a, 64.0, 4095.0))


@FUZZ
@given(k=NUMBERS, n=NUMBERS, first=NUMBERS, seed=NUMBERS)
def test_any_number_into_sensor_frame_and_frames_is_taken_or_refused_in_one_line(k, n, first, seed):
    _ok_or_one_line(lambda: SHOT.frame(k))
    _ok_or_one_line(lambda: list(SHOT.frames(n, first)) if isinstance(n, int) and abs(n) < 3 else SHOT.frames(n, first))
    _ok_or_one_line(lambda: Sensor({"sensor": {"width": 8, "height": 8}}, seed=seed))
    _ok_or_one_line(lambda: SHOT.frame(0, region=(k, n, first, seed)))


@pytest.mark.parametrize("config", [None, 5, "nosuch-preset", {"sensor": {"width": -4}}, {"sensor": 3},
                                    {"nosuch": {}}, ["sensor"], {"sensor": {"width": float("nan")}}])
def test_sensor_of_any_configuration_is_taken_or_refused_in_one_line(config):
    _ok_or_one_line(lambda: Sensor(config))
