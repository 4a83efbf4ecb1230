"""The numbers the README quotes: measured by code in this repository, stored, and rendered into the README.

Each section has a ``compute`` (runs cmosnoise, returns plain data) and a
``render`` (data -> the Markdown between ``<!-- numbers:NAME -->`` and
``<!-- /numbers:NAME -->`` in README.md). Data live in ``docs/numbers/NAME.json``.

    python docs/readme_numbers.py compute [NAME ...]   # measure again, write the JSON
    python docs/readme_numbers.py render               # rewrite the README's blocks from the JSON
    python docs/readme_numbers.py check                # exit 1 if README and JSON disagree

``speed`` is measured by ``benchmarks/bench_chain.py --json docs/numbers/speed.json``
(machine-dependent, never recomputed by tests). The tests check that every
README block is the rendering of its JSON, and recompute the deterministic
sections (``tests/test_readme_numbers.py``), so the README cannot drift.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "docs" / "numbers"
README = ROOT / "README.md"


# ---------------------------------------------------------------- sections
def compute_fig9_map() -> dict:
    """White pixels and couplets of the dark-current map, paper-fig9-vga and -5m, seed 0."""
    from cmosnoise import Sensor, load_config, white_pixels

    out = {}
    for preset in ("paper-fig9-vga", "paper-fig9-5m"):
        sensor = Sensor(load_config(preset=preset), seed=0)
        state = sensor.dark_state
        r = white_pixels.report(sensor.dark_rate, state.threshold, sensor.cfa)
        n = sensor.dark_rate.size
        p = r["white_pixels"] / n
        out[preset] = {
            "pixels": n, "white_pixels": r["white_pixels"], "ppm": r["ppm"], "couplets": r["couplets"],
            "expected": r["couplets_expected_random"], "ppm_se": 1e6 * (p * (1 - p) / n) ** 0.5,
            "threshold_aA": round(state.threshold / 6.241509, 1),
            "map_mean": float(sensor.dark_rate.mean()), "map_max": float(sensor.dark_rate.max()),
            "body_mean": float(state.mean),
        }
    return out


def render_fig9_map(d: dict) -> str:
    thr = {v["threshold_aA"] for v in d.values()}
    head = f"ppm above {thr.pop():g} aA" if len(thr) == 1 else "ppm above threshold"
    lines = [f"| preset | pixels | white pixels (map) | {head} | couplets | expected at random |",
             "|---|---|---|---|---|---|"]
    for preset, v in d.items():
        lines.append(f"| `{preset}` | {_int(v['pixels'])} | {_int(v['white_pixels'])} | {_int(round(v['ppm']))} "
                     f"| {v['couplets']} | {v['expected']:.1f} |")
    se = [f"{round(v['ppm_se'])} ppm at {'VGA' if 'vga' in k else '5 MP'}" for k, v in d.items()]
    lines += ["", f"(seed 0; the binomial standard error of the ppm is {' and '.join(se)}.)"]
    v = d["paper-fig9-5m"]
    lines += ["", f"The presets' 500 e-/s is the body's mean, as the paper prints it; the tail of white pixels "
              f"raises the map's mean to {v['map_mean']:.0f} e-/s (+{100 * (v['map_mean'] / v['body_mean'] - 1):.0f} %), "
              f"and its brightest pixel reaches {_int(round(v['map_max']))} e-/s (body plus up to 80 000 of tail)."]
    return "\n".join(lines)


def compute_dark_budget() -> dict:
    """The default sensor in the dark: predicted total temporal noise and what 4 frames measure (seed 0)."""
    import tempfile

    from cmosnoise.app import cli

    with tempfile.TemporaryDirectory() as tmp:
        code = cli.run(["simulate", "--scene", "flat:0", "--frames", "4", "--seed", "0", "--no-progress",
                        "--out", f"{tmp}/o"])
        assert code == 0
        s = json.loads(Path(f"{tmp}/o/summary.json").read_text())
    return {"predicted_dn": s["temporal_noise"]["predicted_rms_dn"], "measured_dn": s["temporal_noise"]["rms_dn"],
            "pairs": 3}


def render_dark_budget(d: dict) -> str:
    return (f"For the default sensor in the dark (`cmosnoise simulate --scene flat:0 --frames 4`) the budget\n"
            f"predicts {d['predicted_dn']:.3f} DN and three frame pairs measure {d['measured_dn']:.3f} DN.")


def render_speed(d: dict) -> str:
    lines = [f"On the development machine ({d['machine']}; `{d['command']}`):", "",
             "| | frames/s | ms/frame | x reference |", "|---|---|---|---|"]
    for row in d["rows"]:
        lines.append(f"| {row['label']} | {row['fps']:.1f} | {row['ms']:.1f} | {row['ratio']:.2f} |")
    lines += ["", f"Once per sensor, drawing the fixed pattern takes {d['fixed_ms']:.0f} ms; once per scene, "
              f"exposing the photograph {d['expose_ms']:.0f} ms.", "",
              "Processing one 1920 x 1080 frame into an 8-bit picture:", "",
              "| processing | ms/frame |", "|---|---|"]
    for row in d["processing"]:
        lines.append(f"| {row['label']} | {row['ms']:.0f} |")
    return "\n".join(lines)


SECTIONS = {
    "fig9_map": (compute_fig9_map, render_fig9_map),
    "dark_budget": (compute_dark_budget, render_dark_budget),
    "speed": (None, render_speed),
}


# ---------------------------------------------------------------- plumbing
def _int(n: int) -> str:
    return f"{n:,}".replace(",", " ")


def load(name: str) -> dict:
    return json.loads((DATA / f"{name}.json").read_text())


def save(name: str, data: dict) -> None:
    DATA.mkdir(parents=True, exist_ok=True)
    (DATA / f"{name}.json").write_text(json.dumps(data, indent=2) + "\n")


def _pattern(name: str) -> re.Pattern:
    return re.compile(rf"(<!-- numbers:{name} -->)(.*?)(<!-- /numbers:{name} -->)", re.S)


def readme_blocks(text: str) -> dict[str, str]:
    """The README's generated blocks, by name."""
    return {name: m.group(2).strip("\n") for name in SECTIONS if (m := _pattern(name).search(text))}


def rendered(text: str) -> str:
    """README text with every block rendered from its JSON."""
    for name, (_, render) in SECTIONS.items():
        text = _pattern(name).sub(lambda m, n=name, r=render: m.group(1) + "\n" + r(load(n)) + "\n" + m.group(3), text)
    return text


def main(argv: list[str]) -> int:
    cmd, names = (argv[0] if argv else "check"), argv[1:]
    if cmd == "compute":
        for name in names or [n for n, (c, _) in SECTIONS.items() if c]:
            compute = SECTIONS[name][0]
            if compute is None:
                subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_chain.py"),
                                "--json", str(DATA / "speed.json")], check=True)
            else:
                save(name, compute())
            print(f"measured {name}")
        return 0
    text = README.read_text()
    new = rendered(text)
    if cmd == "render":
        README.write_text(new)
        return 0
    if cmd == "check":
        bad = [n for n in SECTIONS if readme_blocks(text).get(n) != readme_blocks(new).get(n)]
        missing = [n for n in SECTIONS if n not in readme_blocks(text)]
        if bad or missing:
            print(f"README out of step: {bad}; blocks missing: {missing}", file=sys.stderr)
            return 1
        return 0
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
