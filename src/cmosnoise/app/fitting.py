"""The ``cmosnoise fit`` job: a data set in, ``config.yaml``, ``fit.json`` and ``fit_report.html`` out.

The round trip: every stack of the measurement is simulated again from the
fitted configuration (same kind, exposure time, temperature, frame count,
and for flats the same mean signal), reduced and fitted the same way, and
each parameter of the two fits is put side by side. For an EMVA 1288 input
the standard's own evaluation (``characterize``) of the measured series is
also set beside that of a series simulated from the fitted configuration.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from statistics import NormalDist

import numpy as np

from ..analysis import characterize as ch
from ..analysis import emva_evaluation as ev
from ..analysis import emva_files
from ..analysis import fit as fitting
from ..config import schema
from ..errors import CmosnoiseError
from ..io import stacks
from ..io.output import OutputFolder, write_json
from ..model.sensor import Sensor
from ..model.spec import resolve
from ..model.stages import random_telegraph
from . import fit_report

#: the frame numbers the round trip's stacks start from (each stack its own range: no shared noise)
ROUND_TRIP_FRAME0 = 10_000_000


def simulate_like(ds, cfg, k_measured: float, seed: int = 0) -> stacks.Dataset:
    """The measurement ``ds`` made again with the sensor ``cfg``: each stack with its kind, exposure, temperature,
    frames and frame period (a stack that gives one is made at that frame rate; its frames can be read again)."""
    sensors: dict = {}
    out = []
    frame = ROUND_TRIP_FRAME0
    for st in ds.stacks:
        T = st.temperature_c if st.temperature_c is not None else cfg.sensor.temperature_c
        rate = None if st.frame_period_s is None else 1.0 / st.frame_period_s
        t = max(st.exposure_s, 1e-9)
        if (T, rate) not in sensors:  # at a frame rate, the sensor's own exposure is the stack's (the timing check)
            sensor = cfg.sensor.model_copy(update={"temperature_c": T, "frame_rate_hz": rate})
            exposure = cfg.exposure if rate is None else cfg.exposure.model_copy(update={"integration_time_s": t})
            sensors[T, rate] = Sensor(cfg.model_copy(update={"sensor": sensor, "exposure": exposure}), seed=seed)
        s = sensors[T, rate]
        if st.kind == "dark":
            ex = s.with_exposure(t).expose("flat:0")
        elif st.kind == "spot":
            ex = s.with_exposure(t, spot_rate(s, t)).expose(spot_scene(s.shape))
        else:
            # the same mean signal as measured: photo-electrons per second that give mean(flat - black) / K
            black = cfg.adc.black_level_dn
            dark_e = float(np.mean(s.dark_rate)) * t if s.dark_rate is not None else 0.0
            photo_e = max((float(st.mean.mean()) - black) / k_measured - dark_e, 0.0)
            ex = s.with_exposure(t, photo_e / t).expose("flat:1.0")

        def frames(ex=ex, first=frame, n=st.n):  # the stack's own frame numbers, bound now
            return (ex.frame(k) for k in range(first, first + n))

        frame += st.n
        reduced = stacks.reduce_stack(frames(), kind=st.kind, exposure_s=st.exposure_s, temperature_c=st.temperature_c,
                                      level=st.level, photons=st.photons, frame_period_s=st.frame_period_s)
        reduced.reread = frames
        out.append(reduced)
    return stacks.Dataset(out, ds.shape, ds.bits, cfg.sensor.cfa, None, "simulated from the fitted configuration", ds.kind)


def spot_scene(shape: tuple[int, int], spacing: int = 7) -> np.ndarray:
    """Single lit pixels on a grid ``spacing`` apart (odd: the lit pixels fall on every CFA colour), CFA signal."""
    scene = np.zeros(shape)
    scene[3:-3:spacing, 3:-3:spacing] = 1.0
    return scene


def spot_rate(sensor, t: float) -> float:
    """Photo-electrons per second that put half the full well in a lit pixel over ``t``."""
    return 0.5 * sensor.saturation_e / t


#: the round trip's false-alarm rate over all of a fit's judged parameters together
ROUND_TRIP_ALARM = 0.01


def _se_towards(p: dict, lo: float, hi: float, other: float) -> float:
    """A value's standard error from its 95 % interval's side that faces ``other`` (intervals may be skewed)."""
    side = hi - p if other >= p else p - lo
    return max(side, 0.0) / 1.959963984540054


def _agree(p: float, lo: float, hi: float, q: float, qlo: float, qhi: float, z: float) -> bool:
    """Whether two independent estimates differ by at most ``z`` standard errors of their difference."""
    se = math.hypot(_se_towards(p, lo, hi, q), _se_towards(q, qlo, qhi, p))
    return abs(p - q) <= z * se


def round_trip(result: dict, again: dict) -> list[dict]:
    """Parameter by parameter: the measured data's fit, the simulated data's fit, and whether they agree.

    Two fits of the same sensor differ by chance: each parameter's two values are judged against the standard
    error of their difference (each value's from its 95 % interval, the side facing the other value), at ``z``
    chosen so that a fit whose every parameter is right raises no alarm in 99 runs of 100 over all its judged
    parameters together (Bonferroni: z = 3.7 for 40 of them). The overlap of two 95 % intervals, judged one
    parameter at a time, raised a false alarm on one fit in seven.
    """
    rows, judged = [], []
    for name, p in result["parameters"].items():
        q = again["parameters"].get(name)
        if q is None or p["value"] is None or q["value"] is None:
            rows.append({"parameter": name, "measured": p["value"], "simulated": None if q is None else q["value"],
                         "agree": None})
            continue
        if isinstance(p["value"], list):  # a kernel or the cell offsets: every element judged
            each = "ci95_pct" if "ci95_pct" in p else "ci95_each"
            a, b = np.asarray(p[each], float), np.asarray(q.get(each, p[each]), float)
            row = {"parameter": name, "measured": p["value"], "simulated": q["value"]}
            a, b = a.reshape(-1, 2), b.reshape(-1, 2)  # each element's interval is symmetric about its value
            judged.append((row, list(zip(a.mean(-1), a, b.mean(-1), b))))
            rows.append(row)
            continue
        if isinstance(p["value"], str):
            if q is not None:
                rows.append({"parameter": name, "measured": p["value"], "simulated": q["value"], "agree": p["value"] == q["value"]})
            continue
        row = {"parameter": name, "measured": float(p["value"]), "simulated": float(q["value"]), "agree": None}
        if p["ci95"] and q["ci95"]:
            judged.append((row, [(float(p["value"]), p["ci95"], float(q["value"]), q["ci95"])]))
        rows.append(row)
    tests = sum(len(pairs) for _, pairs in judged)
    if tests:
        z = NormalDist().inv_cdf(1 - ROUND_TRIP_ALARM / (2 * tests))
        for row, pairs in judged:
            row["agree"] = all(_agree(pv, pi[0], pi[1], qv, qi[0], qi[1], z) for pv, pi, qv, qi in pairs)
    return rows


def emva_round_trip(descriptor: Path, cfg) -> list[dict]:
    """EMVA 1288 quantities of the measured series and of the fitted sensor measured with the same plan (the
    measured exposure times, photons per pixel and stack sizes: :func:`characterize.measure_like`)."""
    m = emva_files.load(descriptor)
    measured = ev.evaluate(m)
    sim = ch.measure_like(Sensor(cfg), m)
    simulated = ev.evaluate(sim)
    rows = []
    ses = [r.get("dsnu_var_se_e2") for r in (measured, simulated)]
    floor = math.hypot(*ses) if all(isinstance(x, float) for x in ses) else None
    for key, label, unit, _fmt in ev.TABLE_ROWS:
        a, b = measured.get(key), simulated.get(key)
        if isinstance(a, (int, float)) and isinstance(b, (int, float)):
            rows.append({"quantity": label.strip(), "unit": unit, "measured": float(a), "simulated": float(b),
                         "agree": ev.agrees(key, float(a), float(b), floor)})
    return rows


def run(frames_from: Path, base, out: Path, overwrite: bool, temperature_c: float | None = None,
        threshold_e_per_s: float | None = None, cfa: str | None = None, black_level_dn: float | None = None,
        bits: int | None = None, with_round_trip: bool = True, seed: int = 0,
        say: Callable[[str], None] = lambda m: None, phase: Callable[[str], None] = lambda m: None,
        truth: Path | None = None) -> dict:
    """Fit ``frames_from`` and write the outputs to ``out`` (whole or not at all).

    ``say`` is told what was done (lines a user keeps); ``phase`` what is being done now (a progress display's
    text: reading, each part of the fit, the round trip, the report). ``truth``: the configuration that made
    the data, compared parameter by parameter (default: :data:`TRUTH_NAME` beside a manifest, where ``cmosnoise
    measure`` put it).
    """
    folder = OutputFolder(out, overwrite)  # refuses a bad output folder before any work
    truth_cfg = None
    phase("reading the stacks")
    ds = stacks.load(frames_from, temperature_c)
    # the truth beside a simulated lab's manifest, or beside its folder of bursts (cmosnoise measure --format dng)
    if truth is None and ds.kind in ("manifest", "bursts") and (Path(frames_from).parent / TRUTH_NAME).is_file():
        truth = Path(frames_from).parent / TRUTH_NAME
    if truth is not None:
        from ..config import load_config

        truth_cfg = load_config(truth)
    if cfa:
        ds.cfa = cfa
    if black_level_dn is not None:
        ds.black_level_dn = black_level_dn
    if bits is not None:
        ds.bits = bits
    say(f"read {len(ds.stacks)} stacks ({sum(s.n for s in ds.stacks)} frames of {ds.shape[1]} x {ds.shape[0]}) "
        f"from {frames_from}")
    # one fit per gain setting the stacks name (a gain table from them), or one fit of the whole
    index, values = ds.settings() or (None, [None])
    parts = {v: ds if v is None else ds.at_setting(index, v) for v in values}
    fits = {}
    for v, sub in parts.items():
        if v is not None:
            say(f"fitting the stacks at {index} {v:g}")
        at = "" if v is None else f" at {index} {v:g}"
        fits[v] = fitting.fit_dataset(sub, base, temperature_c, threshold_e_per_s, seed,
                                      phase=lambda name, at=at: phase(f"fitting{at}: {name}"))
    cfg = fitting.fitted_config(base, fits[None]) if index is None else fitting.fitted_gain_config(base, index, fits)
    result = fits[values[0]]
    trip = emva = None
    if with_round_trip:
        say("round trip: simulating the measurement again from the fitted configuration")
        trip = []
        for v, sub in parts.items():  # each setting's stacks from the fitted sensor at that setting
            at = cfg if v is None else resolve(cfg.model_copy(update={"sensor": cfg.sensor.model_copy(update={index: v})})).config
            where = "" if v is None else f" at {index} {v:g}"
            phase(f"round trip{where}: simulating the measurement from the fitted sensor")
            again = fitting.fit_dataset(simulate_like(sub, at, fits[v]["parameters"]["system_gain_K_dn_per_e"]["value"],
                                                      seed), at, temperature_c, threshold_e_per_s, seed,
                                        phase=lambda name, w=where: phase(f"round trip{w}: fitting again: {name}"))
            prefix = "" if v is None else f"{index} {v:g}: "
            trip += [{**row, "parameter": prefix + row["parameter"]} for row in round_trip(fits[v], again)]
        if ds.kind == "emva" and ds.descriptor is not None:
            phase("round trip: EMVA 1288 of the fitted sensor on the measured plan")
            emva = emva_round_trip(ds.descriptor, cfg)
    per_setting = None if index is None else {
        f"{v:g}": {"parameters": fits[v]["parameters"], "not_fitted": fits[v]["not_fitted"],
                   "mode": next((r.mode for r in cfg.gain_table if getattr(r, index) == v), None)} for v in values}
    doc = {
        "source": str(frames_from), "input": ds.kind, "meta": result["meta"],
        "parameters": result["parameters"], "not_fitted": result["not_fitted"],
        "dark_current": {f"{T:g}": {"threshold_e_per_s": r["threshold"], "families": r["families"],
                                    "white_pixels": r["white_pixels"], "exposures_s": r["exposures_s"]}
                         for T, r in result["dark"].items()},
        "round_trip": trip, "emva_round_trip": emva, "settings": per_setting,
        "selection": result.get("selection", {}),
        "spectra": result.get("spectra", {}),
    }
    if truth_cfg is not None:
        doc["truth"] = {"source": str(truth), "rows": compare_with_truth(result["parameters"], truth_cfg,
                                                                          result["meta"].get("temperatures"))}
    phase("writing fit_report.html")
    html_text = fit_report.build(doc, result, cfg)
    with folder as tmp:
        comments = "".join(f"# {line}\n" for line in provenance_lines(doc))
        (tmp / "config.yaml").write_text(comments + cfg.to_yaml())
        write_json(tmp / "fit.json", doc)
        (tmp / "fit_report.html").write_text(html_text)
    return doc


def describe(p: dict) -> str:
    """One parameter as a line: value, interval (not where it is not identifiable), basis, method."""
    v = p["value"]
    value = f"{v:.5g}" if isinstance(v, float) and math.isfinite(v) else str(v)
    basis = p.get("basis", "measured")
    if basis == "not identifiable":
        return f"{value} [not identifiable: only {p.get('identifiable', 'a combination')} is]: {p['method']}"
    ci = f" (95 % CI {p['ci95'][0]:.4g} to {p['ci95'][1]:.4g})" if p.get("ci95") else ""
    return f"{value}{ci} [{basis}]: {p['method']}"


#: the name of the configuration that made a simulated lab's data (``cmosnoise measure`` writes it beside the
#: manifest; ``fit`` compares with it)
TRUTH_NAME = "truth.yaml"


def truth_values(truth, temperatures: list[float] | None = None) -> dict[str, float]:
    """What each fitted parameter's name means in the configuration ``truth`` (a resolved Config): its number.

    The keys a fit writes as configuration keys (``source_follower.thermal_sigma_e``, ``prnu.sigma_pct``, ...)
    are read from the configuration as they are; K, the black level, the full well and the QE from their
    sections; each fitted temperature's dark-current body (mean, std) from the configuration's characterization
    points at that temperature (``temperatures``: the fit's; default: the points' and the sensor's); the source
    follower's total from its thermal and mean-square flicker sigma. A section switched off gives nothing: its
    numbers did not make the data.
    """
    from ..model import physics
    from ..model.spec import resolve
    from ..model.stages import dark_current

    spec = resolve(truth)
    c = spec.config
    out: dict[str, float] = {"system_gain_K_dn_per_e": spec.transfer.gain_dn_per_e,
                             "black_level_dn": c.adc.black_level_dn, "full_well_e": c.sensor.full_well_e}
    if c.sensor.qe_mean() is not None:
        out["quantum_efficiency"] = c.sensor.qe_mean()
    dump = c.model_dump(mode="json")

    def walk(node, prefix):
        if node.get("enabled") is False:  # a stage that is off: its numbers are not what made the data
            return
        for key, value in node.items():
            name = f"{prefix}{key}"
            if isinstance(value, dict):
                walk(value, name + ".")
            elif isinstance(value, (int, float)) and not isinstance(value, bool):
                out.setdefault(name, float(value))

    for section in ("source_follower", "row_noise", "column_noise", "prnu", "pixel_offset", "black_level"):
        walk(dump[section], section + ".")
    if c.source_follower.enabled:
        ms = 0.0
        if c.source_follower.flicker.enabled:  # E[X^2] of max(B, 0) + Bernoulli(f) Uniform(0, M)
            law = physics.flicker_model(c)
            b1 = float(law.body.expect(lambda x: x, lb=0))
            b2 = float(law.body.expect(lambda x: x * x, lb=0))
            m, f = law.tail_max, law.tail_fraction
            ms = b2 + f * (b1 * m + m * m / 3)
        out["source_follower.read_noise_total_e"] = math.sqrt(c.source_follower.thermal_sigma_e**2 + ms)
    if c.dark_current.enabled:
        d = c.dark_current
        for T in temperatures or sorted({p.temperature_c for p in spec.dark_points} | {c.sensor.temperature_c}):
            state = dark_current.at_temperature(list(spec.dark_points), T, d.doubling_c, d.tail_doubling_c)
            out[f"dark_current[{T:g} C].mean_e_per_s"] = state.mean
            out[f"dark_current[{T:g} C].std_e_per_s"] = state.std
        out["dark_current.doubling_c"] = d.doubling_c
    return out


def compare_with_truth(parameters: dict, truth, temperatures: list[float] | None = None) -> list[dict]:
    """Parameter by parameter: the fitted value and its 95 % interval beside the value of the configuration that
    made the data, and whether the interval holds it (None where the fit gives no interval or the truth has no
    such number). Dark-current rows are made at the fitted temperatures."""
    values = truth_values(truth, temperatures)
    rows = []
    for name, p in parameters.items():
        if name not in values or not isinstance(p.get("value"), (int, float)) or isinstance(p.get("value"), bool):
            continue
        ci = p.get("ci95")
        inside = None if ci is None or p.get("basis") == "not identifiable" else bool(ci[0] <= values[name] <= ci[1])
        rows.append({"parameter": name, "fitted": float(p["value"]), "ci95": ci, "truth": values[name],
                     "inside": inside, "basis": p.get("basis", "measured")})
    return rows


def truth_line(rows: list[dict], source: str) -> str:
    """The comparison with the truth as one line: how many 95 % intervals hold it, and which do not."""
    judged = [r for r in rows if r["inside"] is not None]
    out = [r["parameter"] for r in judged if not r["inside"]]
    expected = 0.05 * len(judged)
    return (f"against the configuration that made the data ({source}): {len(judged) - len(out)} of {len(judged)} "
            f"95 % intervals hold it (about {expected:.1f} miss by chance)" + (f"; outside: {', '.join(out)}" if out else "")
            + (f"; {len(rows) - len(judged)} without an interval" if len(judged) < len(rows) else ""))


def provenance_lines(doc: dict) -> list[str]:
    """What a fitted configuration rests on, as lines (config.yaml's comments): the temperature's basis, then the
    parameters by basis, and what was kept from the base configuration."""
    meta = doc.get("meta", {})
    lines = [f"fitted by cmosnoise fit from {doc.get('source')}",
             f"temperature {meta.get('temperature_c')} C: {meta.get('temperature_basis', 'from the data')}"]
    by: dict[str, list[str]] = {}
    for name, p in doc.get("parameters", {}).items():
        by.setdefault(p.get("basis", "measured"), []).append(name)
    for basis in fitting.BASES:
        if by.get(basis):
            lines.append(f"{basis}: {', '.join(by[basis])}")
    if doc.get("not_fitted"):
        lines.append(f"kept from the base configuration (not in these data): {', '.join(doc['not_fitted'])}")
    lines.append(selection_line(doc.get("selection", {})))
    return lines


def selection_line(selection: dict) -> str:
    """Which stages the data's tests switched on, at what threshold (the console's and config.yaml's line)."""
    from ..analysis.fit import SELECTION_ALPHA, SELECTION_P, SELECTION_TESTS

    on = [f"{name} (p = {t['p_value']:.2g})" for name, t in selection.items() if t["on"]]
    off = [name for name, t in selection.items() if not t["on"]]
    return (f"stages switched on by the data (each test at p < {SELECTION_P:.2g}: {SELECTION_ALPHA:.0%} "
            f"family-wise over {len(SELECTION_TESTS)} tests): {', '.join(on) or 'none'}"
            + (f"; absence not rejected: {', '.join(off)}" if off else ""))


def dark_exposures(sensor: Sensor, base_s: tuple[float, ...] = (0.25, 0.5, 1.0), signal_e: float = 200.0) -> list[float]:
    """Dark-current exposure times (s) for ``sensor``: ``base_s``, and where the body's mean dark signal is below
    ``signal_e`` at the longest of them, ``base_s`` scaled up until it is (never past a third of saturation;
    rounded to 3 significant digits; never past the longest exposure a configuration takes, an hour). The short
    ones measure the white pixels, which clip in the long ones (each pixel's slope is taken where it does not
    clip); the long ones the body, above the read noise."""
    state = sensor.dark_state
    if state is None or state.mean <= 0:
        return list(base_s)
    longest = max(base_s)
    limit = schema.MAX_EXPOSURE_S
    scale = max(1.0, min(signal_e / (state.mean * longest), sensor.saturation_e / 3 / (state.mean * longest),
                         limit / longest))
    if scale <= 1.0:
        return list(base_s)
    return list(base_s) + [float(f"{t * scale:.3g}") for t in base_s]


def write_measurement(cfg, folder: Path, seed: int = 0, temperatures: list[float] | None = None, levels: int = 40,
                      long_frames: int = 100, dark_times: tuple[float, ...] = (0.25, 0.5, 1.0),
                      say: Callable[[str], None] = lambda m: None,
                      progress: Callable[[int, int], None] | None = None, isos: list[float] | None = None,
                      form: str = "npy") -> Path:
    """A lab's measurement of the sensor ``cfg``, simulated, as ``.npy`` stacks and a manifest (what ``fit`` reads).

    At each temperature: a ``long_frames`` dark stack at 5 ms (the readout
    noise, the random telegraph pixels; with its frame period) and 8-frame dark stacks at ``dark_times`` (the dark current),
    and on a cool sensor, as a lab would, at those times lengthened until the
    body's mean dark signal is 200 e- at the longest (:func:`dark_exposures`),
    so the dark signal stands above the read noise. At
    the first temperature also: ``levels`` flat pairs at 5 ms from 2 % to
    130 % of saturation, a 16-frame flat at half saturation (PRNU, column
    gain), an 8-frame stack of single lit pixels 7 apart (crosstalk). Every
    stack has frames of its own. Returns the manifest's path. ``progress(done, total)`` is told the frames
    made.
    ``folder`` is written into as it is (``cmosnoise measure`` gives it an
    output folder's temporary, so the result is whole or absent).

    ``isos``: the whole measurement at each of these settings of the
    camera's gain table (``sensor.iso``), each stack naming its ISO, the
    frames numbered on from one setting to the next. ``form``: ``npy``
    (stacks and ``manifest.yaml``, whose path is returned) or ``dng`` (one
    DNG a frame, ISO and exposure time in its tags, in a folder of bursts
    that :func:`cmosnoise.io.stacks.bursts` reads without a manifest:
    ``bursts/<kind>/iso<ISO>/<stack>/0000.dng``; the folder's path is
    returned). A DNG holds no temperature: that form takes one.
    """
    import yaml

    from ..io.dng import write_dng

    temperatures = temperatures or [cfg.sensor.temperature_c]
    if form not in ("npy", "dng"):
        raise CmosnoiseError(f"--format {form!r}: choose npy (stacks and a manifest) or dng (a folder of bursts)")
    if form == "dng" and len(temperatures) > 1:
        raise CmosnoiseError(f"--temperatures {','.join(f'{t:g}' for t in temperatures)} with --format dng: a DNG "
                             "holds no temperature, so a folder of bursts is one temperature's; give one, or "
                             "--format npy")
    if isos is not None and not cfg.gain_table:
        raise CmosnoiseError(f"--isos {','.join(f'{v:g}' for v in isos)}: the sensor has no gain table to set; "
                             "give a camera that has one (sony-a7s2, sony-imx900) or leave --isos out")
    if form == "dng" and not isos:  # a folder of bursts says each file's ISO: the sensor's own setting
        if cfg.sensor.iso is None:
            raise CmosnoiseError("--format dng writes each burst's ISO in its files: give --isos (settings of the "
                                 "sensor's gain table) or a sensor set to an ISO (sensor.iso)")
        isos = [cfg.sensor.iso]
    settings: list[float | None] = list(isos) if isos else [None]

    def at_iso(v: float | None):
        return cfg if v is None else cfg.model_copy(update={"sensor": cfg.sensor.model_copy(
            update={"iso": v, "gain_db": None})})

    truth = at_iso(min(isos) if isos else None)  # what fit compares with: the lowest setting, its parameters'
    folder.mkdir(parents=True, exist_ok=True)
    stacks_: list[dict] = []
    frame = 0
    # the frames to make (a cool sensor's dark stacks at lengthened times as well are added when found)
    total = len(settings) * (len(temperatures) * (long_frames + 8 * len(dark_times)) + 2 * levels + 16 + 8)

    def save(name: str, ex, n: int, **entry) -> None:
        nonlocal frame
        frames = []
        for i in range(n):
            frames.append(ex.frame(frame + i))
            if progress:
                progress(frame + i + 1, total)
        frame += n
        if form == "npy":
            np.save(folder / name, np.stack(frames))
            stacks_.append(dict(entry, files=[name]))
            return
        t = ex.sensor.transfer
        setting = f"iso{entry['iso']:g}"
        burst = folder / "bursts" / entry["kind"] / setting / Path(name).stem.removeprefix(setting + "_")
        burst.mkdir(parents=True, exist_ok=True)
        for i, f in enumerate(frames):
            write_dng(burst / f"{i:04d}.dng", f, ex.sensor.cfa, t.black_level_dn, t.max_code, iso=entry["iso"],
                      exposure_s=entry["exposure_s"])

    t_flat = 0.005
    for v in settings:
        at = at_iso(v)
        tag: dict = {} if v is None else {"iso": v}
        pre = "" if v is None else f"iso{v:g}_"
        for j, T in enumerate(temperatures):
            s = Sensor(at.model_copy(update={"sensor": at.sensor.model_copy(update={"temperature_c": T})}), seed=seed)
            # the long stack's frame period: its random telegraph pixels' dwell times are counted in it
            save(f"{pre}dark_{T:g}C_{t_flat:g}s.npy", s.with_exposure(t_flat).expose("flat:0"), long_frames,
                 kind="dark", exposure_s=t_flat, temperature_c=T, **tag,
                 frame_period_s=random_telegraph.frame_period_s(cfg.sensor.frame_rate_hz, t_flat))
            times = dark_exposures(s, dark_times)
            total += 8 * (len(times) - len(dark_times))
            for t in times:
                save(f"{pre}dark_{T:g}C_{t:g}s.npy", s.with_exposure(t).expose("flat:0"), 8, kind="dark",
                     exposure_s=t, temperature_c=T, **tag)
            if j == 0:
                for i, lvl in enumerate(np.linspace(0.02, 1.3, levels)):
                    ex = s.with_exposure(t_flat, s.saturation_e * float(lvl) / t_flat).expose("flat:1.0")
                    save(f"{pre}flat_{i:03d}.npy", ex, 2, kind="flat", exposure_s=t_flat, temperature_c=T, **tag,
                         level=round(float(lvl), 4))
                ex = s.with_exposure(t_flat, s.saturation_e * 0.5 / t_flat).expose("flat:1.0")
                save(f"{pre}flat_half.npy", ex, 16, kind="flat", exposure_s=t_flat, temperature_c=T, **tag, level=0.5)
                ex = s.with_exposure(t_flat, spot_rate(s, t_flat)).expose(spot_scene(s.shape))
                save(f"{pre}spots.npy", ex, 8, kind="spot", exposure_s=t_flat, temperature_c=T, **tag)
            say(f"wrote the stacks at {T:g} C" + ("" if v is None else f", ISO {v:g}"))
    if form == "dng":
        (folder / TRUTH_NAME).write_text("# the configuration that made these bursts: cmosnoise fit compares with "
                                         "it\n" + truth.to_yaml())
        return folder / "bursts"
    manifest = folder / "manifest.yaml"
    # the files' range (a 14-bit ADC written in 16 bits: 16; the fit finds the ADC's bits from the codes' spacing)
    doc = {"cfa": cfg.sensor.cfa, "bits": cfg.adc.output_bits or cfg.adc.bits, "black_level_dn": cfg.adc.black_level_dn,
           "stacks": stacks_}
    manifest.write_text(f"# a simulated lab measurement (cmosnoise measure); the configuration that made it: "
                        f"{TRUTH_NAME}\n" + yaml.safe_dump(doc, sort_keys=False))
    (folder / TRUTH_NAME).write_text("# the configuration that made these stacks: cmosnoise fit compares with it\n"
                                     + truth.to_yaml())
    return manifest
