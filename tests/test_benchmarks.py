"""Benchmarks that cannot rot (#58): every script in benchmarks/ runs at its smallest size here (slow tier), so a
refactor that breaks one fails a test. bench_sweep.py called a function that no longer existed and nothing noticed.

The numbers are not checked (they are the machine's); that each script runs to its end, and prints, is. Scripts
whose smallest run is still minutes long (a whole fit's coverage study, the explorer in a browser, the GPU's
checks) are imported and asked for --help: their imports and arguments at least are held.
"""

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"

#: script -> its smallest run's arguments
SMALLEST = {
    "bench_chain.py": ["--frames", "2", "--repeats", "1", "--cli-frames", "2", "--cli-repeats", "1", "--width",
                       "320", "--height", "180"],
    "bench_dataset.py": ["--samples", "2", "--crop", "64", "--repeats", "1"],
    "bench_flicker.py": ["--frames", "2", "--repeats", "1"],
    "bench_measured_stages.py": ["--frames", "2", "--repeats", "1"],
    "bench_telegraph.py": ["--frames", "2", "--repeats", "1"],
    "bench_run.py": ["--megapixels", "1", "--repeats", "1"],
    "bench_optics.py": ["--megapixels", "0.1", "--repeats", "1", "--memory-megapixels", "0.1"],
    "bench_quality.py": ["--megapixels", "0.1", "--repeats", "1", "--chart-frames", "2"],
    "bench_setup.py": ["--sizes", "1", "--repeats", "1"],
    "bench_sweep.py": ["--instances", "2"],
    "bias_source_follower.py": ["--fits", "2", "--frames", "8"],
    "fit_telegraph_coverage.py": ["--sensors", "1", "--size", "64"],
    "fit_selection.py": ["--seeds", "1"],
    "kernel_parts.py": ["--repeats", "1"],
}
#: minutes at their smallest (or a device they need): imported and --help only
HELP_ONLY = {"bench_compile_load.py": "a whole build on an empty cache, minutes under load",
             "bench_explore.py": "a browser and 1080p panes", "bench_fit.py": "a whole VGA fit, twice",
             "bench_gpu.py": "an NVIDIA GPU (benchmarks/gpu_check.sh)", "bench_tiles.py": "50 MP at its smallest",
             "fit_coverage.py": "hundreds of fits"}


def test_every_benchmark_script_is_in_one_of_the_two_lists():
    scripts = {p.name for p in BENCH.glob("*.py")}
    assert scripts == set(SMALLEST) | set(HELP_ONLY), scripts ^ (set(SMALLEST) | set(HELP_ONLY))


@pytest.mark.slow
@pytest.mark.parametrize("script", sorted(SMALLEST))
def test_a_benchmark_runs_at_its_smallest_size(script, tmp_path):
    r = subprocess.run([sys.executable, str(BENCH / script), *SMALLEST[script]], capture_output=True, text=True,
                       cwd=tmp_path, timeout=600)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-3000:])
    assert r.stdout.strip(), "a benchmark prints what it measured"


@pytest.mark.parametrize("script", sorted(HELP_ONLY))
def test_a_long_benchmark_imports_and_parses_its_arguments(script, tmp_path):
    r = subprocess.run([sys.executable, str(BENCH / script), "--help"], capture_output=True, text=True,
                       cwd=tmp_path, timeout=300)
    assert r.returncode == 0 and "usage" in r.stdout, (r.stdout[-2000:], r.stderr[-3000:])
