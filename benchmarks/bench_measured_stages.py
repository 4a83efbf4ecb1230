"""What the stages of measured sensors cost the frame kernel, at 1920 x 1080 RGGB.

The default chain is timed with every measured-sensor stage off, and again with pixel offsets, black-level
offsets per CFA cell (and the frame's black-level error), the nonlinearity and Tukey-lambda read noise after
the gain all on; each against the plain NumPy reference of bench_chain.py timed alternately with it, so the
ratio of the two ratios is the stages' cost, free of a shared machine's slow spells.

    python benchmarks/bench_measured_stages.py [--frames 20] [--repeats 5] [--threads 2] [--json FILE]
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

from bench_chain import cost_arguments, save_cost, stage_cost  # noqa: E402

ALL_ON = {
    "pixel_offset": {"enabled": True, "sigma_e": 3.0, "tail": {"ppm_above": 200, "threshold_e": 20, "max_e": 200}},
    "black_level": {"channel_offsets_dn": [1.5, -0.5, 0.25, 2.0], "frame_sigma_dn": 0.05},
    "nonlinearity": {"enabled": True, "linearity_error_pct": [-1.13, 0.6]},
    "read_noise": {"enabled": True, "distribution": "tukey_lambda", "scale_dn": 0.7, "shape": 0.149},
}


def main() -> None:
    a = cost_arguments(__doc__, "also write the results here (docs/numbers/measured_stages.json feeds the README)")
    rows, cost = stage_cost(a, "every measured-sensor stage off (the default)",
                            "offsets, cell black levels, nonlinearity, Tukey-lambda read noise on", ALL_ON)
    print(f"the stages cost {100 * cost:+.1f} % per frame ({a.threads} threads)")
    save_cost(a, rows, cost)


if __name__ == "__main__":
    main()
