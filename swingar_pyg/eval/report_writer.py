"""Writes a report folder from measured results: ``report.md`` (tables and
plots, with the machine, versions, seeds and commands), CSV tables, PNG plots
and ``report.json`` (every figure), each file atomically."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import torch

from swingar_pyg.atomic import atomic_path
from swingar_pyg.eval.error_vs_time import setting_name, simulator_front
from swingar_pyg.eval.stability import as_dicts, stability_summary, stability_table
from swingar_pyg.training.vertex_errors import error_stats, garment_family


def _write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _write_csv(path: Path, rows: list[dict]) -> None:
    if not rows:
        return
    buffer = io.StringIO()
    columns = list(dict.fromkeys(k for row in rows for k in row))
    writer = csv.DictWriter(buffer, fieldnames=columns)
    writer.writeheader()
    writer.writerows(rows)
    _write_text(path, buffer.getvalue())


def _save(figure, path: Path) -> None:
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format="png", dpi=120, bbox_inches="tight")


def _figure(figsize: tuple[float, float], columns: int = 1):
    """A figure on an Agg canvas of its own (pyplot's backend is left alone)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=figsize)
    FigureCanvasAgg(figure)
    return figure, figure.subplots(1, columns)


def _groups(result, sequences, key) -> dict[str, torch.Tensor]:
    by = {}
    for s in sequences:
        if s.id in result.errors:
            by.setdefault(key(s), []).append(result.errors[s.id].reshape(-1))
    return {k: torch.cat(v) for k, v in by.items()}


def _garment(s) -> str:
    return s.garment.name


def _motion(s) -> str:
    return s.motion.name


def _family(s) -> str:
    return garment_family(s.garment.name)


def seed_interval(values: list[float], level: float = 0.95) -> tuple[float, float | None]:
    """The mean of one figure over ``n`` seeds and the half-width of its
    Student-t confidence interval, ``t_{(1+level)/2, n-1} · s / sqrt(n)`` with
    ``s`` the sample standard deviation; ``None`` for a single seed."""
    from scipy.stats import t

    values = np.asarray(values, dtype=float)
    if len(values) < 2:
        return float(values.mean()), None
    half = t.ppf((1 + level) / 2, len(values) - 1) * values.std(ddof=1) / np.sqrt(len(values))
    return float(values.mean()), float(half)


def seed_rows(per_model, rigid, sequences) -> list[dict]:
    """Per model and garment family (``all`` first): the seeds' mean vertex error
    (mm) and its ratio to rigid skinning, each with its 95 % confidence interval."""

    def family_means(result) -> dict[str, float]:
        means = {k: float(v.mean()) for k, v in _groups(result, sequences, _family).items()}
        means["all"] = float(torch.cat([e.reshape(-1) for e in result.errors.values()]).mean())
        return means

    reference = family_means(rigid)
    families = ["all"] + sorted(k for k in reference if k != "all")
    rows = []
    for label, runs in per_model.items():
        per_run = [family_means(run) for run in runs]
        for family in families:
            mean, half = seed_interval([means[family] for means in per_run])
            rows.append({"method": label, "family": family, "seeds": len(runs),
                         "mean_mm": mean, "ci95_mm": half,
                         "ratio_to_rigid": mean / reference[family],
                         "ci95_ratio": None if half is None else half / reference[family]})
    return rows


def _seed_table(rows: list[dict]) -> list[str]:
    families = list(dict.fromkeys(r["family"] for r in rows))
    lines = ["## Over seeds", "",
             "Mean vertex error (mm) and its ratio to rigid skinning, averaged over the seeds, "
             "± the half-width of the 95 % Student-t confidence interval over seeds "
             "(`seeds.csv`).", "",
             "| method | seeds | " + " | ".join(families) + " |",
             "|---|---|" + "---|" * len(families)]
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = {r["family"]: r for r in rows if r["method"] == method}
        cells = []
        for family in families:
            r = mine[family]
            if r["ci95_mm"] is None:
                cells.append(f"{r['mean_mm']:.1f} mm, {r['ratio_to_rigid']:.2f}x")
            else:
                cells.append(f"{r['mean_mm']:.1f} ± {r['ci95_mm']:.1f} mm, "
                             f"{r['ratio_to_rigid']:.2f} ± {r['ci95_ratio']:.2f}x")
        lines.append(f"| {method} | {mine['all']['seeds']} | " + " | ".join(cells) + " |")
    return lines + [""]


def plot_error_vs_time(results, rigid, simulator, second, floor, simulated):
    """Every method on the sequences the simulator re-ran, so the points compare; the
    simulator's settings as points, joined along its Pareto front (what the equal-error
    speed-up interpolates)."""
    from matplotlib.ticker import ScalarFormatter

    figure, axis = _figure((8.5, 5))
    axis.scatter([r.ms_per_frame for r in simulator],
                 [r.stats(simulated)["mean_mm"] for r in simulator], color="grey", zorder=2,
                 label="simulator at other substeps x iterations")
    front = simulator_front(simulator)
    axis.plot([ms for _, ms in front], [error for error, _ in front], "-", color="grey",
              label="the simulator's Pareto front")
    for result in simulator:
        tag = " (ground truth's setting)" if result.extra["is_ground_truth_setting"] else ""
        axis.annotate(result.name.split()[-1] + tag,
                      (result.ms_per_frame, result.stats(simulated)["mean_mm"]), fontsize=7,
                      xytext=(4, 3), textcoords="offset points")
    axis.scatter([rigid.ms_per_frame], [rigid.stats(simulated)["mean_mm"]], marker="s",
                 color="black", label="rigid skinning", zorder=3)
    if second is not None:
        axis.scatter([second.ms_per_frame], [second.stats(simulated)["mean_mm"]], marker="D",
                     color="dimgrey", label=second.name, zorder=3)
    for k, result in enumerate(results):
        # distinct markers: an fp32 and a bf16 run often land on the same spot
        axis.scatter([result.ms_per_frame], [result.stats(simulated)["mean_mm"]], s=50, zorder=3,
                     color=f"C{k}", marker="o^vPX"[k % 5], label=result.name)
    if floor is not None:
        axis.axhline(floor["mean_mm"], color="black", lw=1, ls=":",
                     label=f"noise floor: {floor['name']}")
    axis.set(xscale="log", yscale="log", xlabel="ms per frame (this machine, one thread)",
             ylabel="mean vertex error vs ground truth (mm)",
             title=f"error against run time ({len(simulated)} re-simulated test sequences)")
    axis.yaxis.set_major_formatter(ScalarFormatter())
    axis.yaxis.set_minor_formatter(ScalarFormatter())
    axis.grid(alpha=0.3, which="both")
    axis.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    figure.tight_layout()
    return figure


def plot_per_garment(per_model, rigid, sequences):
    garments = sorted({_garment(s) for s in sequences})
    labels = list(per_model) + ["rigid skinning"]
    figure, axis = _figure((max(7.0, 1.6 * len(garments) * len(labels) / 3), 4.5))
    width = 0.8 / len(labels)
    for k, label in enumerate(labels):
        runs = per_model.get(label, [rigid])
        per_seed = [_groups(r, sequences, _garment) for r in runs]
        means = np.array([[float(g[name].mean()) for name in garments] for g in per_seed])
        axis.bar(np.arange(len(garments)) + (k - len(labels) / 2 + 0.5) * width, means.mean(0),
                 width, yerr=means.std(0) if len(runs) > 1 else None, capsize=3,
                 label=f"{label} ({len(runs)} seed{'s' if len(runs) > 1 else ''})"
                 if label in per_model else label, color="black" if label == "rigid skinning"
                 else f"C{k}")
    axis.set_xticks(range(len(garments)), [g.replace("@", "\n@") for g in garments], fontsize=7)
    axis.set(ylabel="mean vertex error (mm)", title="per garment (bars: spread over seeds)")
    axis.legend(fontsize=7)
    figure.tight_layout()
    return figure


def plot_distributions(results, rigid):
    figure, axis = _figure((7.5, 4.5))
    everything = [(r.name, torch.cat([e.reshape(-1) for e in r.errors.values()]))
                  for r in results] + [("rigid skinning", torch.cat(
                      [e.reshape(-1) for e in rigid.errors.values()]))]
    top = max(float(e.max()) for _, e in everything)
    bins = np.logspace(-1, np.log10(max(top, 1.0)), 60)
    for k, (name, errors) in enumerate(everything):
        axis.hist(errors.clamp_min(0.1).numpy(), bins=bins, histtype="step", density=True,
                  lw=1.4, label=name, color="black" if name == "rigid skinning" else f"C{k}")
    axis.set(xscale="log", xlabel="per-vertex error (mm)", ylabel="density",
             title="distribution of per-vertex errors, every test frame")
    axis.legend(fontsize=7)
    figure.tight_layout()
    return figure


def plot_streaming(streaming):
    figure, axis = _figure((5.5, 4))
    for compiled in sorted({r["compiled"] for r in streaming}):
        rows = [r for r in streaming if r["compiled"] == compiled]
        axis.plot([r["vertices"] for r in rows], [r["fps"] for r in rows], "o-",
                  label="torch.compile" if compiled else "eager")
        for r in rows:
            axis.annotate(f"{r['fps']:.1f} fps", (r["vertices"], r["fps"]), fontsize=7,
                          xytext=(3, 3), textcoords="offset points")
    axis.set(xscale="log", yscale="log", xlabel="garment vertices",
             ylabel="frames per second (streaming, one thread)", title="streaming speed")
    axis.grid(alpha=0.3, which="both")
    axis.legend(fontsize=7)
    figure.tight_layout()
    return figure


def _times(ratio: float) -> str:
    """A speed-up: ``123x``, or two significant digits below 10 (``7x``, ``0.18x``),
    so a slow-down stays visible."""
    return f"{ratio:.0f}x" if ratio >= 10 else f"{ratio:.2g}x"


def _fmt(stats: dict) -> str:
    return f"{stats['mean_mm']:.1f} / {stats['rmse_mm']:.1f} / {stats['p95_mm']:.1f}"


def _provenance(resumed: dict[str, str]) -> str:
    """Where the figures come from: this run, or for the estimator measurements
    in ``resumed`` (label -> when) an earlier run of the report (``--resume``)."""
    if not resumed:
        return "Every figure below was measured in this run, on this machine."
    listed = "; ".join(f"{label}, on {when}" for label, when in resumed.items())
    return (f"Every figure below was measured in this run, on this machine, except "
            f"{len(resumed)} estimator measurement(s) read back with `--resume` from "
            f"`measured/`, where an earlier run of this report stored them: {listed}. Their "
            "errors and times are as measured then, by the same code on the same machine "
            "and torch threads, but under that run's load; their equal-error speed-ups "
            "set those times against this run's simulator times (`measured_at` in the CSV).")


def write_report(out: Path, config, *, machine, test_path, sequences, results, per_model,
                 rigid, simulator, second, simulated, speedups, streaming, extra, stability,
                 checkpoints, body_sdf, seconds, resumed=None) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    finest = max(simulator, key=lambda r: r.extra["substeps"] * r.extra["iterations"])
    floor = None
    if not finest.extra["is_ground_truth_setting"]:
        floor = {"name": f"{finest.name} vs the ground truth's setting", **finest.stats()}
    rows = [r.row() for r in results] + [rigid.row()] + [r.row() for r in simulator]
    if second is not None:
        rows.append(second.row())
    _write_csv(out / "error_vs_time.csv", rows)
    garment_rows = []
    for label, runs in list(per_model.items()) + [("rigid skinning", [rigid])]:
        for run in runs:
            for key, group in (("garment", _garment), ("motion", _motion)):
                for name, errors in _groups(run, sequences, group).items():
                    garment_rows.append({"method": label, "seed": run.extra.get("seed", ""),
                                         key: name, **error_stats(errors)})
    _write_csv(out / "per_garment.csv", [r for r in garment_rows if "garment" in r])
    _write_csv(out / "per_motion.csv", [r for r in garment_rows if "motion" in r])
    _write_csv(out / "streaming.csv", streaming)
    _write_csv(out / "stability.csv", as_dicts(stability))
    over_seeds = seed_rows(per_model, rigid, sequences)
    several_seeds = any(r["seeds"] > 1 for r in over_seeds)
    if several_seeds:
        _write_csv(out / "seeds.csv", over_seeds)
    else:  # not a table of an earlier report into this folder
        (out / "seeds.csv").unlink(missing_ok=True)
    _save(plot_error_vs_time(results, rigid, simulator, second, floor, simulated),
          out / "error_vs_time.png")
    _save(plot_per_garment(per_model, rigid, sequences), out / "per_garment.png")
    _save(plot_distributions(results, rigid), out / "distributions.png")
    if streaming:
        _save(plot_streaming(streaming), out / "streaming.png")

    garments = sorted({_garment(s) for s in sequences})
    motions = sorted({_motion(s) for s in sequences})
    frames = sum(len(s.truth) for s in sequences)
    stored = sequences[0].settings
    truth_setting = setting_name(stored["substeps"], stored["iterations"],
                                 stored.get("max_substeps"))
    lines = [
        f"# Report: {config.name}",
        "",
        f"Made by `swingar report -c <config>` (report `{config.name}`) on {machine['date']}, "
        f"{machine['platform']} ({machine['processor']}), Python {machine['python']}, torch "
        f"{machine['versions']['torch']}, {machine['torch_threads']} torch thread(s), in "
        f"{seconds / 60:.1f} min. " + _provenance(resumed or {}),
        "",
        f"Test split `{test_path}`: {len(garments)} garment(s) x {len(motions)} motion(s) "
        f"never seen in training, {len(sequences)} sequences, {frames} frames; ground truth "
        f"from the XPBD simulator at {truth_setting} (substeps x iterations"
        + (f", a frame that ends above {100 * stored['target_stretch']:g} % stretch re-run at "
           "twice the substeps up to the number after the colon"
           + (f", until a re-run ends above {stored['stall_ratio']:g} times the previous "
              "run's largest strain (the frame keeps its least stretched run)"
              if stored.get("stall_ratio") else "")
           if stored.get("max_substeps") else "") + ").",
        "",
        "Models: " + "; ".join(f"{k}: `{v}`" for k, v in checkpoints.items()) +
        (f"; body SDF: `{body_sdf}`" if body_sdf else "") + ".",
        "",
        "## Error against run time",
        "",
        "![error against run time](error_vs_time.png)",
        "",
        "| method | error mean / RMSE / p95 (mm) | ms per frame | vertices inside the body |"
        " equal-error speed-up over the simulator |",
        "|---|---|---|---|---|",
    ]
    for result in results:
        speedup = speedups[result.name]
        inside = result.extra.get("inside_percent")
        lines.append(
            f"| {result.name} | {_fmt(result.stats())} | {result.ms_per_frame:.1f} | "
            f"{'' if inside is None else f'{inside:.2f} %'} | "
            f"{_times(speedup['speedup']) if speedup['speedup'] else speedup['note']} |")
    lines.append(f"| rigid skinning | {_fmt(rigid.stats())} | {rigid.ms_per_frame:.2f} | | |")
    for result in simulator:
        tag = " (the ground truth's own setting, re-run from the stored float32 garment)" \
            if result.extra["is_ground_truth_setting"] else ""
        lines.append(f"| {result.name}{tag} | {_fmt(result.stats())} | "
                     f"{result.ms_per_frame:.0f} | | largest strain "
                     f"{100 * result.extra['max_strain']:.0f} % |")
    if second is not None:
        lines.append(f"| {second.name} | {_fmt(second.stats())} | {second.ms_per_frame:.0f} | "
                     f"| largest strain {100 * second.extra['max_strain']:.0f} % |")
    lines += [
        "",
        f"The simulator rows re-ran {len(simulated)} sequences "
        f"({', '.join(s.id for s in simulated)}) with other substeps and iterations; errors "
        "are against the stored ground truth. The plot shows every method on those sequences "
        "(the table: on the whole split), and the equal-error speed-up interpolates the "
        "simulator's time at the estimator's mean error on them (log-log). Re-run at its own "
        "setting, the simulator differs from the ground truth only through the float32 "
        "rounding of the stored garment it starts from: cloth is chaotic, so that difference "
        "is itself a floor.",
    ]
    if floor is not None:
        lines.append(f"Noise floor: the finest setting, {finest.name}, differs from the ground "
                     f"truth by {floor['mean_mm']:.1f} mm on average (p95 "
                     f"{floor['p95_mm']:.1f} mm): no method's error is meaningful below that. "
                     + ("" if second is not None else
                        "A second simulator's disagreement, the other floor, is not measured "
                        "in this run (config `simulator.second`; or "
                        "`benchmarks/bench_sim_crosscheck.py`)."))
    if second is not None:
        stats = second.stats()
        lines.append(f"Second simulator: {second.name}, on the same scenes with the same "
                     f"frame rate, gravity, density, damping, friction and thickness, differs "
                     f"from the ground truth by {stats['mean_mm']:.1f} mm on average (p95 "
                     f"{stats['p95_mm']:.1f} mm): the floor two credible cloth models set "
                     f"(largest strain {100 * second.extra['max_strain']:.0f} %).")
    families = sorted({_family(s) for s in sequences})
    lines += ["", "## Per garment family, garment and motion", "",
              "| method | " + " | ".join(f"{f} mean / p95 (mm)" for f in families) + " |",
              "|---|" + "---|" * len(families)]
    for label, runs in list(per_model.items()) + [("rigid skinning", [rigid])]:
        cells = []
        for family in families:
            stats = [error_stats(_groups(r, sequences, _family)[family]) for r in runs]
            cells.append(f"{np.mean([x['mean_mm'] for x in stats]):.1f} / "
                         f"{np.mean([x['p95_mm'] for x in stats]):.1f}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += ["", "![per garment](per_garment.png)", "",
              "| method | " + " | ".join(garments) + " |", "|---|" + "---|" * len(garments)]
    for label, runs in list(per_model.items()) + [("rigid skinning", [rigid])]:
        cells = []
        for name in garments:
            means = [float(_groups(r, sequences, _garment)[name].mean()) for r in runs]
            cells.append(f"{np.mean(means):.1f}" + (f" ± {np.std(means):.1f}"
                                                     if len(means) > 1 else ""))
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += ["", "| method | " + " | ".join(motions) + " |", "|---|" + "---|" * len(motions)]
    for label, runs in list(per_model.items()) + [("rigid skinning", [rigid])]:
        cells = [f"{np.mean([float(_groups(r, sequences, _motion)[m].mean()) for r in runs]):.1f}"
                 for m in motions]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += ["", "Mean vertex error in mm (± the standard deviation over seeds where there are "
              "several). Per-vertex error distributions:", "",
              "![distributions](distributions.png)", ""]
    if several_seeds:
        lines += _seed_table(over_seeds)
    if streaming:
        stages = [k for k in streaming[0] if k.startswith("ms ")]
        lines += ["## Streaming speed", "", "![streaming](streaming.png)", "",
                  "Median per frame after warm-up (`swingar_pyg.eval.stream_speed`).", "",
                  "| vertices | compiled | ms per frame | fps | " +
                  " | ".join(f"{k[3:]} ms" for k in stages) + " |",
                  "|---" * (4 + len(stages)) + "|"]
        lines += [f"| {r['vertices']} | {'yes' if r['compiled'] else 'no'} | "
                  f"{r['ms_per_frame']:.1f} | {r['fps']:.1f} | " +
                  " | ".join(f"{r.get(k, 0.0):.2f}" for k in stages) + " |"
                  for r in streaming]
        lines.append("")
    for name, rows_ in extra.items():
        lines += [f"## {name}", "", "| method | error mean / RMSE / p95 (mm) | ms per frame |",
                  "|---|---|---|"]
        for row in rows_["estimators"] + [rows_["rigid"]]:
            lines.append(f"| {row['method']} | {row['mean_mm']:.1f} / {row['rmse_mm']:.1f} / "
                         f"{row['p95_mm']:.1f} | {row['ms_per_frame']:.1f} |")
        lines.append("")
    if stability:
        lines += ["## Stability suite", "", stability_summary(stability) + ".", "",
                  stability_table(stability), ""]
    seeds = (" --seeds " + " ".join(map(str, config.seeds_override))
             if config.seeds_override else "")
    lines += ["## Reproduce", "", "```bash", "OMP_NUM_THREADS=1 .venv/bin/swingar report -c "
              f"configs/report/{config.name}.yaml{seeds}", "```", ""]
    report = out / "report.md"
    _write_text(report, "\n".join(lines))
    payload = {"config": {k: v for k, v in config.__dict__.items() if k != "models"},
               "models": [m.__dict__ for m in config.models], "machine": machine,
               "test_split": str(test_path), "checkpoints": checkpoints,
               "resumed": resumed or {}, "body_sdf": body_sdf,
               "results": rows, "speedups": speedups, "streaming": streaming, "extra": extra,
               "stability": as_dicts(stability), "over_seeds": over_seeds, "seconds": seconds}
    _write_text(out / "report.json", json.dumps(payload, indent=2, default=str))
    return report
