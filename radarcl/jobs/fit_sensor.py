"""`radarcl fit-sensor`: a real radar's background law and sensitivity fitted from its own scans
(``evaluation.sensor_fit``), written as a configuration whose every fitted value says where it
came from and how well the recording determines it."""

import dataclasses
import math
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.evaluation import sensor_fit
from radarcl.io import polar_png


def scan_selection(text, n):
    """The scan indices of ``text``, a Python slice "A:B" or "A:B:S" (empty parts: the ends; "all"),
    of a recording of ``n`` scans; a sentence when it selects none or lies outside."""
    if text in (None, "", "all"):
        return list(range(n))
    parts = text.split(":")
    try:
        if len(parts) not in (2, 3):
            raise ValueError
        a, b, *s = (int(p) if p.strip() else None for p in parts)
    except ValueError:
        raise ConfigError(f"--scans {text!r}: expected A:B or A:B:S (Python slice of the scans in time order, "
                          f"e.g. 0:6 or 0::2)") from None
    step = s[0] if s else None
    if step is not None and step <= 0:
        raise ConfigError(f"--scans {text!r}: the step must be positive")
    for v in (a, b):
        if v is not None and not -n <= v <= n:
            raise ConfigError(f"--scans {text!r}: the recording has {n} scans (0 to {n - 1})")
    chosen = list(range(n))[slice(a, b, step)]
    if not chosen:
        raise ConfigError(f"--scans {text!r} selects no scan of the {n}")
    return chosen


SENSITIVITY_GRID_DB = tuple(range(10, 111, 10))
LOOK_LIMITS = (1.0, 2.0)
BACKGROUND = ("clutter_share", "clutter_db", "clutter_spread_db", "noise_scale")   # fitted together
PHANTOM_LIMIT = 0.10            # a map with --lidar calls at most this share of the lidar's free cells occupied
CHOICE_RANGE_M = 30.0           # in every band to this range (where a fog lidar still reaches)


def run(config, data_dir, scans="all", lidar=False, runtime=None, report=None):
    """The fit of ``config``'s sensor (a ``Resolved``) on the scans of ``data_dir`` that ``scans``
    selects, with the recording's lidar (``lidar``: the background from the cells it calls free,
    the sensitivity from those it calls occupied; then the map's sensitivity, look limit and
    clutter chosen with the lidar's cells, ``choose_by_lidar``, on ``runtime``):
    (the fitted configuration, a dict of the fit for --json and the table)."""
    say = report or (lambda _: None)
    sensor = config.sensor
    if sensor.raw or sensor.input != "profiles":
        raise ConfigError(f"fit-sensor reads polar scans (a Navtech-like profile); sensor {sensor.name} is "
                          f"{sensor.input}")
    try:
        sequence = polar_png.read_sequence(data_dir, polar_png.PolarLayout.of(sensor), odometry=False)
    except FrameFormatError as e:
        hint = ("; RADIATE's recordings (Navtech_Polar/) are read with --sensor radiate-cts350x"
                if (Path(data_dir) / "Navtech_Polar").is_dir() and sensor.name != "radiate-cts350x" else "")
        raise FrameFormatError(f"{e}{hint}") from None
    chosen = scan_selection(scans, len(sequence.scans))
    say(f"{len(sequence.scans)} scans in {sequence.directory}; fitting on scans {span(chosen)} ({len(chosen)})")
    if config.sensor.n_bins() is None:
        config = config.for_sensor(config.sensor.with_bins(sequence.scans[chosen[0]].n_bins))
    lo, hi = config["interpret.range_min_m"], config["interpret.range_max_m"]
    background = targets = None
    if lidar:
        powers, free, occupied = _lidar_bins(config, data_dir, chosen, say)
        background = sensor_fit.power_counts(powers, config.bin_spacing_m, lo, hi, mask=free)
        targets = sensor_fit.power_counts(powers, config.bin_spacing_m, lo, hi, mask=occupied)
    else:
        powers = []
        for k in chosen:
            scan = sequence.scans[k]
            powers.append(np.asarray(scan.power(), np.float64)[np.asarray(scan.valid, bool)])
    counts = sensor_fit.power_counts(powers, config.bin_spacing_m, lo, hi)
    geometry = sensor_fit.Geometry(config.model_params(), math.radians(sensor.get("beams", "beamwidth_az_deg")) / 2,
                                   math.radians(sensor.get("beams", "beamwidth_el_deg")) / 2)
    result = sensor_fit.fit(counts, geometry, report=say, background=background, targets=targets)
    source = f"radarcl fit-sensor{' --lidar' if lidar else ''} on scans {span(chosen)} of {sequence.directory}"
    fitted = config.replaced(**{k.replace(".", "__"): v for k, v in result.config_values().items()})
    fit_origins = {}
    for key, value, se in zip(sensor_fit.FITTED, result.values, result.errors):
        bounded = "at the search's edge: the recording does not bound it" if key in result.at_edge else \
            f"+- {1.96 * se:.2g} (1.96 jackknife SEs over {result.n_scans} scans of one recording)"
        fit_origins[f"sensor_model.{key}"] = f"{source}: {value:.4g} {bounded}"
    origins = {**fitted.origins, **fit_origins}
    out = dict(sensor=sensor.name, data=str(sequence.directory), scans=chosen, n_powers=result.n_powers,
               lidar=lidar, fit=result.as_dict(), at_edge=list(result.at_edge), target_shares=list(result.shares),
               band_ranges_m=[float(r) for r in counts.ranges_m[:, 1]],
               log_likelihood=result.log_likelihood, noise_only_log_likelihood=result.noise_only)
    if lidar:
        out.update(background_powers=int(background.counts.sum()), target_powers=int(targets.counts.sum()))
        values, chosen_origins, out["maps"] = choose_by_lidar(runtime, fitted, data_dir, chosen, result, source, say)
        if values["sensor_model.clutter_share"] == 0.0:         # noise alone: the fitted law is unused, not written
            values.update({f"sensor_model.{k}": config[f"sensor_model.{k}"] for k in BACKGROUND[1:3]})
        fitted = fitted.replaced(**{k.replace(".", "__"): v for k, v in values.items()})
        origins = {**fitted.origins, **fit_origins, **chosen_origins}
    else:
        # what the scans do not bound stays the configuration's: the background's four values were fitted
        # together, so one at its edge keeps them all; the map's sensitivity and look limit need a truth
        # to choose (the powers' typical target is not the map's: Oxford's fitted 106 dB erased its
        # facades; held-out detections reward a map that calls nothing occupied: docs/guide/sensor-models.md)
        kept = set(result.at_edge) | {"snr_1m2_at_10m_db"}
        if kept & set(BACKGROUND):
            kept |= set(BACKGROUND)
        fitted = fitted.replaced(**{f"sensor_model__{k}": config[f"sensor_model.{k}"] for k in kept})
        origins = {**fitted.origins, **fit_origins}
        for k in kept:
            why = ("at its search's edge" if k in result.at_edge else
                   "not the map's: chosen with a lidar only (--lidar)" if k == "snr_1m2_at_10m_db" else
                   "fitted together with a value at its edge")
            origins[f"sensor_model.{k}"] = f"{config.origins[f'sensor_model.{k}']} (kept: the fit's was {why})"
        origins["sensor_model.look_limit"] = config.origins["sensor_model.look_limit"]
        out["kept"] = sorted(kept)
    for key in ("block_gamma_db", "blocker_gap"):
        origins[f"sensor_model.{key}"] += "; not fitted (what lies behind a first surface has no truth here)"
    return dataclasses.replace(fitted, origins=origins), out


def candidates_of(config, result):
    """{label: (values, configuration)} of the maps the choice compares: ``SENSITIVITY_GRID_DB`` x
    ``LOOK_LIMITS`` x (noise alone, the fitted background of ``result``)."""
    fitted = dict(zip(sensor_fit.FITTED, result.values))
    clutter = {f"sensor_model.{k}": fitted[k] for k in ("clutter_share", "clutter_db", "clutter_spread_db",
                                                         "noise_scale")}
    none = {"sensor_model.clutter_share": 0.0, "sensor_model.noise_scale": 1.0}
    out = {}
    for sensitivity in SENSITIVITY_GRID_DB:
        for limit in LOOK_LIMITS:
            for name, extra in (("no clutter", none), ("the fitted background", clutter)):
                values = {"sensor_model.snr_1m2_at_10m_db": float(sensitivity), "sensor_model.look_limit": limit,
                          **extra}
                label = f"{sensitivity:g} dB, look limit {limit:g}, {name}"
                out[label] = (values, config.replaced(**{k.replace(".", "__"): v for k, v in values.items()}))
    return out


def _noise_only_origins(values, why, result):
    if values["sensor_model.clutter_share"] != 0.0:
        return {}
    unused = f"{why}: noise alone, the fitted law unused (share {result.values[0]:.3g}, median " \
             f"{result.values[1]:.3g} dB, spread {result.values[2]:.3g} dB)"
    return {"sensor_model.clutter_share": unused, "sensor_model.clutter_db": unused,
            "sensor_model.clutter_spread_db": unused, "sensor_model.noise_scale": f"{why}: noise alone sets the floor"}


def choose_by_lidar(runtime, config, data_dir, chosen, result, source, say):
    """The map's parameters by what a robot meets where the lidar knows, on the fit's scans:
    over ``SENSITIVITY_GRID_DB`` x ``LOOK_LIMITS`` x (no clutter, the fitted background), among
    the maps that call at most ``PHANTOM_LIMIT`` of the lidar-free cells occupied in every band to
    ``CHOICE_RANGE_M`` (a robot stops for nothing there; ``evaluation.lidar.costmap_scores``), the
    one that ranks the lidar's occupied cells above its free ones best: the mean over the bands of
    the ROC area of its log-odds (a map blind in a band ranks at 0.5 there). Their recall, misses
    and likelihood of the lidar's cells are reported beside. Returns (its values, their origins, the
    rows of every candidate); refuses when no candidate keeps the phantoms within the limit."""
    from radarcl.evaluation import lidar as L
    from radarcl.evaluation.heldout import log_likelihood
    from radarcl.evaluation.metrics import roc_auc
    from radarcl.jobs.evaluate_lidar import run as evaluate

    candidates = candidates_of(config, result)
    say(f"choosing with the lidar: {len(candidates)} maps of scans {span(chosen)} ...")
    _, arrays = evaluate(runtime, [(label, c) for label, (_, c) in candidates.items()], data_dir,
                         voxel_m=config["grid.voxel_m"], scan_slice=(chosen[0], chosen[-1] + 1),
                         report=lambda *_: None)
    truth = arrays["truth"]
    distance = L.range_from_path(truth.spec, arrays["per_beam"][..., :3, 3].reshape(-1, 3))
    bands = [(distance >= lo) & (distance < hi) for lo, hi in zip(L.BANDS_M[:-1], L.BANDS_M[1:])
             if hi <= CHOICE_RANGE_M]
    rows = []
    for label in candidates:
        nats, known = arrays["maps"][label], arrays["known"].get(label)
        scores = [L.costmap_scores(nats, truth.occupied & band, truth.free & band, known) for band in bands]
        aucs = [roc_auc(nats[band & truth.known], truth.occupied[band & truth.known]) for band in bands]
        rows.append(dict(candidate=label, auc=float(np.nanmean(aucs)),
                         recall=float(np.nanmean([s["recall"] for s in scores])),
                         blind=bool(any(s["recall"] == 0 for s in scores)),
                         miss=float(np.nanmean([s["miss"] for s in scores])),
                         phantom=float(np.nanmax([s["phantom"] for s in scores])),
                         log_likelihood=log_likelihood(nats[truth.known], truth.occupied[truth.known])))
    best = best_candidate(rows, f"every band to {CHOICE_RANGE_M:g} m on scans {span(chosen)}")
    values = candidates[best["candidate"]][0]
    why = (f"{source}: of {len(rows)} maps the best ranking of the lidar's occupied cells above its free ones (ROC "
           f"area {best['auc']:.3f}, the mean over the bands to {CHOICE_RANGE_M:g} m) among those calling at most "
           f"{PHANTOM_LIMIT:g} of the free ones occupied and some occupied ones occupied in every band")
    chosen_origins = {"sensor_model.snr_1m2_at_10m_db": why, "sensor_model.look_limit": why,
                      **_noise_only_origins(values, why, result)}
    return values, chosen_origins, dict(chosen=best["candidate"], cells=int(truth.known.sum()), candidates=rows,
                                        phantom_limit=PHANTOM_LIMIT, range_m=CHOICE_RANGE_M)


def best_candidate(rows, where):
    """The row of the best ROC area (then log-likelihood) among the candidates that call at most
    ``PHANTOM_LIMIT`` of the lidar's free cells occupied and are not blind in any band. A map that
    calls nothing occupied in a band meets the phantom limit trivially and may still rank well, but
    a robot would drive into every obstacle there. Refuses when none qualifies."""
    admissible = [r for r in rows if r["phantom"] <= PHANTOM_LIMIT and not r["blind"]]
    if not admissible:
        raise ConfigError(f"no map of the {len(rows)} candidates keeps its phantom rate within {PHANTOM_LIMIT:g} in "
                          f"{where} while calling some of the lidar's occupied cells occupied in each (the least "
                          f"phantom rate: {min(r['phantom'] for r in rows):.3f})")
    return max(admissible, key=lambda r: (r["auc"], r["log_likelihood"]))


def _lidar_bins(config, data_dir, chosen, say):
    """(powers, free, occupied) per scan of ``chosen`` (a contiguous run): each scan's power of its
    measured azimuths and the bins whose cell of the lidar's truth (``evaluate_lidar.lidar_part``,
    on the configuration's voxel) is free, occupied."""
    from radarcl.evaluation.lidar import bin_cells
    from radarcl.jobs.evaluate_lidar import lidar_part

    if len(chosen) > 1 and set(np.diff(chosen)) != {1}:
        raise ConfigError("--lidar takes a run of consecutive scans (A:B): the lidar frames are those taken "
                          "meanwhile")
    source, _, _, truth = lidar_part(config.sensor, data_dir, config["grid.voxel_m"],
                                     scan_slice=(chosen[0], chosen[-1] + 1), report=say)
    ranges = np.arange(source.frames.scans[0].n_bins) * config.bin_spacing_m
    powers, free, occupied = [], [], []
    for scan, poses in zip(source.frames.scans, source.poses):
        valid = np.asarray(scan.valid, bool)                   # measured azimuths only, as without a lidar
        iy, ix, inside = (a[valid] for a in bin_cells(truth.spec, poses, ranges))
        powers.append(np.asarray(scan.power(), np.float64)[valid])
        free.append(inside & truth.free[iy, ix])
        occupied.append(inside & truth.occupied[iy, ix])
    return powers, free, occupied


def span(chosen):
    """Scan indices as a person reads them: "0-10 every 2", or a list."""
    if len(chosen) > 1 and len(set(np.diff(chosen))) == 1:
        step = chosen[1] - chosen[0]
        return f"{chosen[0]}-{chosen[-1]}" + (f" every {step}" if step > 1 else "")
    return ", ".join(map(str, chosen))


def format_lines(out):
    """The fit as tables a person reads at a glance: what the powers say, what the lidar chose,
    what the configuration holds."""
    names = {"clutter_share": ("clutter share", ""), "clutter_db": ("clutter median", "dB over the floor"),
             "clutter_spread_db": ("clutter spread", "dB"), "snr_1m2_at_10m_db": ("sensitivity", "dB, 1 m^2 at 10 m"),
             "noise_scale": ("noise scale", "x the floor (median / ln 2)")}
    how = (f"the background from the {out['background_powers']:,} bins of cells the lidar calls free, the sensitivity "
           f"from the {out['target_powers']:,} of cells it calls occupied" if out["lidar"] else
           "the mixture of background and typical targets per band of range")
    lines = [f"{out['sensor']}, scans {span(out['scans'])}: {out['n_powers']:,} powers; by maximum likelihood of "
             f"{how}:", f"  {'parameter':<16} {'value':>9} {'about 95 %':>21}  unit"]
    for key, (label, unit) in names.items():
        v, se = out["fit"][key]["value"], out["fit"][key]["se"]
        interval = "not bounded" if key in out["at_edge"] else f"[{v - 1.96 * se:.4g}, {v + 1.96 * se:.4g}]"
        lines.append(f"  {label:<16} {v:>9.4g} {interval:>21}  {unit}")
    if out["at_edge"]:
        lines.append(f"  at the search's edge, so not bounded by these scans: {', '.join(out['at_edge'])}")
    lines.append(f"  log-likelihood per power {out['log_likelihood']:.4f} nat (no clutter, the rest as fitted: "
                 f"{out['noise_only_log_likelihood']:.4f}); share of bins holding a typical target by range: "
                 + ", ".join(f"{r:.0f} m {s:.2f}" for r, s in zip(out["band_ranges_m"], out["target_shares"])))
    m = out.get("maps")
    if not m:
        kept = f" ({', '.join(out['kept'])} kept)" if out.get("kept") else ""
        lines.append(f"written: the fitted background where the scans bound it; the map's sensitivity, its look "
                     f"limit and the rest stay the configuration's{kept}: without a lidar nothing here tells a map "
                     "that finds obstacles from one that does not (with RADIATE's lidar the fitted background ranked "
                     "worse than noise alone: docs/guide/sensor-models.md). Check a map made with it: "
                     "`radarcl navtech-map --config FILE` (its half-map check), or `radarcl evaluate-lidar --model FILE` "
                     "where the recording has a lidar.")
    else:
        rows = sorted(m["candidates"], key=lambda r: (r["phantom"] > m["phantom_limit"] or r.get("blind", False),
                                                      -r["auc"]))
        lines.append(f"the map's sensitivity, look limit and background with the lidar's {m['cells']:,} cells: the "
                     f"best ranking of its occupied cells above its free ones (ROC area, the mean over the bands to "
                     f"{m['range_m']:g} m) with at most {m['phantom_limit']:g} of the free ones and some of the occupied ones "
                     f"called occupied in every band (best 5 of {len(rows)}):")
        lines.append(f"  {'AUC':>6} {'recall':>6} {'miss':>6} {'phantom':>7} {'log-lik':>8}  map")
        lines += [f"  {r['auc']:6.3f} {r['recall']:6.3f} {r['miss']:6.3f} {r['phantom']:7.3f} {r['log_likelihood']:8.4f}  "
                  f"{r['candidate']}" + _verdict(r, m) for r in rows[:5]]
    return lines


def _verdict(row, maps):
    """Why a candidate of the lidar's choice was or was not taken, for its table's line."""
    if row["candidate"] == maps["chosen"]:
        return "   <- chosen"
    if row.get("blind", False):
        return "   (calls none occupied in a band)"
    return "   (too many phantoms)" if row["phantom"] > maps["phantom_limit"] else ""
