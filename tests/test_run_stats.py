"""Run statistics: the fused one-pass sums give the EMVA definitions, on any number of threads."""

import numba
import numpy as np
import pytest

from cmosnoise.analysis import emva
from cmosnoise.analysis.run_stats import RunStats, frame_sums, frame_sums_numpy


def _frames(dtype, n=4, shape=(61, 83)):
    rng = np.random.default_rng(5)
    base = rng.uniform(100, 3000, shape)
    out = []
    for _ in range(n):
        e = (base + rng.normal(0, 20, shape)).astype(np.float32)
        raw = np.clip(np.rint(e * 1.3 + 64), 0, 4095).astype(dtype)
        out.append((raw, e))
    return out


@pytest.mark.parametrize("dtype", [np.uint16, np.float32])
def test_run_stats_match_the_definitions(dtype):
    frames = _frames(dtype)
    frames[0][0][:3, :3] = 4095  # some saturated codes
    st = RunStats(4095)
    for raw, e in frames:
        st.update(raw, e)
    r = st.result()
    tv_dn = np.mean([emva.temporal_variance(a[0], b[0]) for a, b in zip(frames[1:], frames[:-1])])
    tv_e = np.mean([emva.temporal_variance(a[1], b[1]) for a, b in zip(frames[1:], frames[:-1])])
    assert r["temporal_noise_dn"] == pytest.approx(np.sqrt(tv_dn), rel=1e-9)
    assert r["temporal_noise_e"] == pytest.approx(np.sqrt(tv_e), rel=1e-9)
    assert r["mean_dn"] == pytest.approx(np.mean([f[0].astype(float).mean() for f in frames]), rel=1e-12)
    assert r["mean_e"] == pytest.approx(np.mean([f[1].astype(float).mean() for f in frames]), rel=1e-12)
    sat = sum(int((f[0] >= 4095).sum()) for f in frames)
    assert sat >= 9 and r["saturated_fraction"] == sat / (len(frames) * frames[0][0].size)


def test_one_frame_has_no_temporal_noise():
    st = RunStats(4095)
    st.update(*_frames(np.uint16, 1)[0])
    assert st.result()["temporal_noise_e"] is None and st.result()["frames"] == 1


def test_frame_sums_same_bits_on_1_and_2_threads_and_close_to_numpy():
    (a, ea), (b, eb) = _frames(np.uint16, 2, (300, 257))
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = frame_sums(a, ea, b, eb, 4095)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = frame_sums(a, ea, b, eb, 4095)
    finally:
        numba.set_num_threads(threads)
    assert one.tobytes() == two.tobytes()
    np.testing.assert_allclose(one, frame_sums_numpy(a, ea, b, eb, 4095), rtol=1e-10, atol=1e-6)
