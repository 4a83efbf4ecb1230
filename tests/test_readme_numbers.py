"""The README's numbers come from docs/readme_numbers.py: the blocks match their data, and the data match the code."""

import importlib.util
import json
from pathlib import Path

import pytest
from conftest import Z

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("readme_numbers", ROOT / "docs" / "readme_numbers.py")
numbers = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(numbers)


def test_every_block_is_in_a_page_and_rendered_from_its_data():
    blocks = numbers.page_blocks()
    assert set(blocks) == set(numbers.SECTIONS), "a numbers block is missing from the pages"
    for path in numbers.pages():
        text = path.read_text()
        fresh = numbers.readme_blocks(numbers.rendered(text))
        for name, block in numbers.readme_blocks(text).items():
            assert block == fresh[name], f"{path.name}: block {name!r} is stale: run python docs/readme_numbers.py render"


def test_check_command_fails_on_a_hand_edited_number(tmp_path, monkeypatch):
    copies = []
    for path in numbers.pages():
        copy = tmp_path / f"{len(copies)}-{path.name}"
        copy.write_text(path.read_text().replace("| `paper-fig9-vga` | 307 200 |", "| `paper-fig9-vga` | 307 201 |"))
        copies.append(copy)
    assert any(c.read_text() != p.read_text() for c, p in zip(copies, numbers.pages()))
    monkeypatch.setattr(numbers, "ROOT", tmp_path)
    monkeypatch.setattr(numbers, "pages", lambda: copies)
    assert numbers.main(["check"]) == 1
    monkeypatch.undo()
    assert numbers.main(["check"]) == 0


@pytest.mark.parametrize("name", [n for n, (compute, _) in numbers.SECTIONS.items() if compute is not None
                                  and n not in numbers.SLOW and n != "quality_hot"])
@pytest.mark.slow
def test_stored_numbers_are_what_the_code_gives_now(name):
    """Deterministic (fixed seeds): measuring again gives the stored data to 9 digits."""
    stored = numbers.load(name)
    again = json.loads(json.dumps(numbers.SECTIONS[name][0]()))
    assert again == pytest.approx(stored, rel=1e-9) if not isinstance(stored, dict) else _close(again, stored)


def _close(a, b):
    if isinstance(b, dict):
        assert a.keys() == b.keys()
        return all(_close(a[k], b[k]) for k in b)
    if isinstance(b, list):  # a table's rows: each value to 9 digits (a CSV's round trip may move the 15th)
        assert len(a) == len(b)
        return all(_close(x, y) for x, y in zip(a, b))
    if isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-9, abs=1e-12)
        return True
    assert a == b
    return True


@pytest.mark.parametrize("name,vectors", [("speed", "AVX-512"), ("speed_avx2", "AVX2")])
def test_speed_data_has_every_row_the_issue_asks_for(name, vectors):
    """The speed tables are measured (benchmarks/, minutes, on a named CPU) and cannot be re-run here: this
    checks that the stored measurement is complete and self-consistent (a row's ratio is its own time over
    the reference timed beside it), which a hand edit or a partial re-measurement breaks."""
    data = numbers.load(name)
    assert data["vectors"] == vectors  # each table is measured on the kind of CPU its name says
    rows = [r["label"] for r in data["rows"]]
    assert any("1 thread" in r for r in rows) and any("2 thread" in r for r in rows)
    assert any(r.startswith("cmosnoise simulate") for r in rows) and any("reference" in r for r in rows)
    for r in data["rows"]:  # each ratio is to the reference timed alongside that row
        assert abs(r["ratio"] - r["ms"] / r["ref_ms"]) <= 1e-9 * r["ratio"], r


@pytest.mark.parametrize("name", ["measured_stages", "telegraph_cost"])
def test_stage_cost_data_is_self_consistent(name):
    """A stage-cost table (benchmarks/, not re-run here): each ratio is its row's time over the reference timed
    beside it, and the cost is the ratio of the two ratios; a hand edit or a partial re-measurement breaks it."""
    data = numbers.load(name)
    for r in data["rows"]:
        assert abs(r["ratio"] - r["ms"] / r["ref_ms"]) <= 1e-9 * r["ratio"], r
    off, on = data["rows"]
    assert abs(data["cost"] - (on["ratio"] / off["ratio"] - 1)) <= 1e-9


def test_the_telegraph_fit_summary_counts_its_rows():
    """The fit's coverage table (benchmarks/fit_telegraph_coverage.py, minutes): each count is the number of its
    sensors' rows that passed."""
    data = numbers.load("telegraph_fit")
    for key, count in data["summary"].items():
        assert count == sum(bool(r[key]) for r in data["rows"]), key


def test_the_fig9_sweep_shows_what_the_paper_shows():
    """Stored by `compute sweep_fig9` (a few minutes, too slow for the suite): the README's claims hold for
    the stored data, so a re-measurement that breaks them fails here. More couplets at 5 MP than at VGA and
    at higher temperatures; each mean within Z standard errors of the count expected at random placement
    (standard error: the instances' spread over sqrt(instances), floored at one count)."""
    pts = numbers.load("sweep_fig9")["points"]
    by = {(p["width"], p["temperature_c"]): p for p in pts}
    temps = sorted({p["temperature_c"] for p in pts})
    for t in temps:
        assert by[(2592, t)]["couplets_mean"] > by[(640, t)]["couplets_mean"]
    for w in (640, 2592):
        means = [by[(w, t)]["couplets_mean"] for t in temps]
        assert means == sorted(means) and means[0] < means[-1]
    for p in pts:
        se = max(p["couplets_std"], 1.0) / p["instances"] ** 0.5
        assert abs(p["couplets_mean"] - p["expected_mean"]) <= Z * se, p


@pytest.mark.slow
def test_the_quality_comparisons_first_instances_are_what_the_code_gives_now():
    """quality_hot's table of the first instance at 25 C and at 65 C, its SNR10s and the visual threshold,
    recomputed alone (2 of its 6 measurements: 53 s of the suite for all six): each instance's seed is its own,
    so these are the stored study's values, to 9 digits. (The differences over the 3 instances are
    ``app.quality.difference`` of the stored measurements; its statistics are tested in test_quality.py.)"""
    stored = numbers.load("quality_hot")
    again = json.loads(json.dumps(numbers.compute_quality_hot(instances=1)))
    assert again.keys() == stored.keys() - {"diff"}
    assert _close(again, {k: stored[k] for k in again})


@pytest.mark.slow
def test_the_quality_yields_point_nearest_its_spec_is_what_the_code_gives_now():
    """quality_yield's point of 0.7 e- column FPN (banding nearest the 1 JND spec), its ten instances recomputed
    alone: each instance's seed is the same in any sweep, so the row is the stored study's, to 9 digits."""
    stored = numbers.load("quality_yield")
    again = json.loads(json.dumps(numbers.compute_quality_yield(values=[0.7])))
    (point,) = again["points"]
    assert _close(point, next(p for p in stored["points"] if p["vfpn_sigma_e"] == 0.7))
