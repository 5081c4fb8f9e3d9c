"""``eskin-bus evaluate``: score detection methods on the scene suite."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import click
import numpy as np

from ..evaluation.charts import CHARTS
from ..evaluation.suite import (
    DEFAULT_SETTINGS,
    EVALUATION_SEEDS,
    HOLD_EVALUATION_SEEDS,
    HOLD_FRESH_SEEDS,
    HOLD_SCENES,
    HOLD_TUNING_SEEDS,
    SUITE,
    TUNING_SEEDS,
    by_name,
    evaluate,
)
from ..methods import detector_names, method_names
from .common import complete_profile, open_profile
from .completion import complete_scene
from .console import Ticker, echo_json, json_alias
from .evaluate_families import family_names, leave_one_out, list_families, per_family, slip_episodes


def _seeds(value: str) -> tuple[int, ...]:
    if value == "evaluation":
        return EVALUATION_SEEDS
    if value == "tuning":
        return TUNING_SEEDS
    seeds: list[int] = []
    try:
        for item in value.split(","):  # N or N..M, any mix: 0..4,7,10..59
            if ".." in item:
                a, b = item.split("..")
                seeds.extend(range(int(a), int(b) + 1))
            else:
                seeds.append(int(item))
    except ValueError:
        raise click.BadParameter(f"expected 'evaluation', 'tuning' or seeds such as 0..4,7,10..59, got {value!r}") from None
    return tuple(seeds)


@click.command()
@click.option("-m", "--method", "methods", multiple=True,
              type=click.Choice(sorted(method_names()) + ["fixed", "oracle"]),
              help="Method to score (repeatable; default: every detector, not the 'none' baseline; with "
                   "--closed-loop also the baselines fixed and oracle, and all of them by default).")
@click.option("-s", "--scene", "scenes", multiple=True, shell_complete=complete_scene, help="Scene (repeatable; default: the built-in suite).")
@click.option("--seeds", default="evaluation", show_default=True,
              help="'evaluation' (held out), 'tuning', or seeds and ranges: 0..4,7,10..59")
@click.option("--rate", "rate_hz", type=click.FloatRange(min=1.0), default=100.0, show_default=True)
@click.option("--tolerance", "tolerance_s", type=float, default=0.5, show_default=True,
              help="A slip flag up to this long after a slip ends still counts as found.")
@click.option("--per-scene", is_flag=True, help="Also print each scene's figures.")
@click.option("--charts", "charts_dir", type=click.Path(file_okay=False), default=None,
              help="Regenerate the evaluation charts (PNG) into this directory instead (a few minutes).")
@click.option("--quick", is_flag=True, help="With --charts: fewer seeds.")
@click.option("--only", "only_charts", multiple=True, type=click.Choice(CHARTS),
              help="With --charts: draw only these (repeatable); 'timing' is the state policy's timing diagrams "
                   "of docs/plc.md (seconds).")
@click.option("--long-holds", is_flag=True,
              help="False alarms over hours of still holding instead: the hold scenes over 100 held-out seeds "
                   "(2000-2099, 3.8 h; with --seeds tuning, the 300 tuning seeds 100-399, 11.3 h; with --seeds fresh, "
                   "100 more held out, 2100-2199), "
                   "about 25 s per 100 seeds and method.")
@click.option("-p", "--profile", "profile_path", type=click.Path(dir_okay=False), default=None, shell_complete=complete_profile,
              help="Take the detector settings from this profile's [detector] (default: the built-in defaults).")
@click.option("--condition", "conditions", multiple=True, metavar="NAME=VALUE",
              help="Push one property of every scene as the failure map does (repeatable), e.g. noise=0.1, "
                   "vibration=0.3, drops=0.2, dead=8, force=0.15, onset=1, ripple=0.08 (evaluation/conditions.py).")
@click.option("--within", "within_ms", multiple=True, type=click.IntRange(min=0),
              help="Also print the share of slip events found within this many ms of onset (repeatable).")
@click.option("--families", "show_families", is_flag=True, help="List the effect families and exit.")
@click.option("--per-family", is_flag=True,
              help="Each method per effect family instead of per suite (the families' scenes, their effect on).")
@click.option("--family", "family_opt", multiple=True,
              help="With --per-family: only this family (repeatable; 'new': the new physics; default: all).")
@click.option("--hold-out-family", "hold_out", multiple=True,
              help="Leave-one-family-out (repeatable; 'all', 'new'): choose the deciding method's setting on the "
                   "tuning seeds of the other families, report it on this family's held-out seeds.")
@click.option("--oracle", is_flag=True,
              help="Also the delay's bound: an oracle that knows each slide's onset and path and its noise, "
                   "at the ramp channel's threshold (evaluation/bound.py), as rows of their own: one watching the "
                   "centre of force, one the whole distribution (turns too).")
@click.option("--format", "fmt", type=click.Choice(["md", "json"]), default="md", show_default=True,
              help="Markdown tables, or one JSON document (every figure, per scene too).")
@click.option("--closed-loop", is_flag=True,
              help="The closed loop instead: each method in the virtual cell, whose gripper reacts (docs/cell.md): "
                   "objects held, dropped and crushed, distance slid, needless squeezes, grip against the fixed grip; "
                   "--seeds evaluation, fresh and tuning are its own (9000-9399, 9400-9799, 8000-8199).")
@click.option("--plc-cycle", "plc_cycle_ms", type=click.FloatRange(min=1.0, max=100.0), default=10.0, show_default=True,
              help="With --closed-loop: the PLC's scan cycle (ms).")
@click.option("--cell", "cell", multiple=True, metavar="NAME=VALUE",
              help="With --closed-loop: change the cell (repeatable): actuator_rate (N/s), dead_time (ms), latency "
                   "(ms added), mass, friction, accel (x the recipe's), viscous (s/m, 0: pure Coulomb), stribeck "
                   "(mm/s, 0: none), force_drop (share lost at a slide's onset), gripper (ideal, small, coarse).")
@click.option("--sweep", type=click.Choice(["rate", "plc-cycle", "actuator", "dead-time", "friction", "mass", "latency",
                                            "viscous", "stribeck", "force-drop", "gripper"]), default=None,
              help="With --closed-loop: one sweep of docs/evaluation.md (default controls: fixed, none, the default "
                   "method, oracle).")
@click.option("--jobs", type=click.IntRange(min=1, max=64), default=None,
              help="With --closed-loop: worker processes (default 1; the figures do not depend on it).")
@click.option("--tune", is_flag=True,
              help="With --closed-loop: remake the recipes' choices on the tuning seeds (the fixed grip's safety "
                   "factor, the grip policy's factors; 20-40 minutes with --jobs 2).")
@json_alias
def evaluate_cmd(methods: tuple[str, ...], scenes: tuple[str, ...], seeds: str, rate_hz: float, tolerance_s: float,
                 per_scene: bool, charts_dir: str | None, quick: bool, only_charts: tuple[str, ...], long_holds: bool,
                 profile_path: str | None, conditions: tuple[str, ...], within_ms: tuple[int, ...],
                 show_families: bool, per_family: bool, family_opt: tuple[str, ...], hold_out: tuple[str, ...],
                 oracle: bool, fmt: str, closed_loop: bool, plc_cycle_ms: float, cell: tuple[str, ...], sweep: str | None,
                 jobs: int | None, tune: bool) -> None:
    """Event-level slip F1, false alarms per hour of holding, detection delay, varying
    force read as slip, and cost per frame, for each method; then how steady the
    reported state is: varying-force episodes found, their time read as varying force,
    state changes per episode, per minute in varying force and in still holds.

    With --closed-loop: each method in the virtual cell instead, beside the fixed grip,
    the light grip with no sensing (none) and the oracle."""
    from .evaluate_closed_loop import check_options

    plc_cycle_set = click.get_current_context().get_parameter_source("plc_cycle_ms") != \
        click.core.ParameterSource.DEFAULT
    check_options(closed_loop, per_family=per_family, hold_out=hold_out, long_holds=long_holds, per_scene=per_scene,
                  scenes=scenes, conditions=conditions, within_ms=within_ms, only_charts=only_charts, cell=cell,
                  sweep=sweep, jobs_set=jobs is not None, plc_cycle_set=plc_cycle_set, tune=tune)
    if closed_loop:
        from .evaluate_closed_loop import closed_loop as run_closed_loop

        if profile_path:
            raise click.UsageError("--closed-loop takes each object's built-in profile: leave out --profile")
        run_closed_loop(methods, seeds, _seeds, rate_hz, plc_cycle_ms, cell, sweep, jobs or 1, charts_dir, fmt, tune)
        return
    if any(m in ("fixed", "oracle") for m in methods):
        raise click.UsageError("fixed and oracle are the closed loop's baselines: give --closed-loop too")
    if show_families:
        list_families()
        return
    if hold_out or per_family:
        _families(methods, scenes, seeds, rate_hz, tolerance_s, long_holds, profile_path, per_family, family_opt,
                  hold_out, fmt, per_scene, within_ms, conditions, oracle)
        return
    if charts_dir is not None:
        from ..evaluation.charts import all_charts

        with Ticker() as ticker:  # the lines of the log above a bar per chart
            all_charts(Path(charts_dir), ticker.write, quick=quick, only=only_charts, progress=ticker)
        return
    if only_charts:
        raise click.UsageError("--only chooses among the charts: give --charts DIR too")
    if long_holds:
        if scenes:
            raise click.UsageError("--long-holds scores the hold scenes; leave out --scene")
        scenes = HOLD_SCENES
        seed_set = ({"tuning": HOLD_TUNING_SEEDS, "evaluation": HOLD_EVALUATION_SEEDS, "fresh": HOLD_FRESH_SEEDS}
                    .get(seeds) or _seeds(seeds))
        seeds = {"tuning": "tuning-holds", "evaluation": "evaluation-holds", "fresh": "fresh-holds"}.get(seeds, seeds)
        methods = methods or ("cof-track", "paper")
    else:
        seed_set = _seeds(seeds)
    names = methods or detector_names()
    start = time.perf_counter()
    if "learned" in names:
        names = _prepare_learned(names)
    settings = open_profile(profile_path).detector if profile_path else DEFAULT_SETTINGS
    scene_set = tuple(scenes) or SUITE
    with Ticker(len(scene_set) * len(seed_set) * len(names), "scoring") as ticker:
        res = evaluate(by_name(*names), scenes=scene_set, seeds=seed_set, rate_hz=rate_hz,
                       tolerance_s=tolerance_s, settings=settings, spec_hook=_conditions(conditions),
                       progress=ticker)
    held = sum(r.score.holding_s for r in res.values()) / max(1, len(res)) / 3600
    bound = _oracle(scene_set, seed_set, rate_hz, settings, _conditions(conditions)) if oracle else None
    if fmt == "json":
        echo_json({"seeds": seeds, "seed_list": list(seed_set), "rate_hz": rate_hz, "scenes": list(scene_set),
                   "conditions": list(conditions), "holding_h": held, "seconds": time.perf_counter() - start,
                   "methods": [_json_row(r, res, within_ms) for r in res.values()],
                   **({oracle_key(path): _oracle_json(*b, settings, within_ms) for path, b in bound.items()}
                      if bound else {})})
        return
    click.echo(f"# eskin-bus evaluate --seeds {seeds} --rate {rate_hz:g}"
               + "".join(f" --condition {c}" for c in conditions) + "  "
               f"({len(scenes) or len(SUITE)} scenes x {len(seed_set)} seeds, {held:.2f} h of holding, "
               f"{time.perf_counter() - start:.0f} s)")
    click.echo("| method | events | found | F1 | false alarms (per h holding) | varying force as slip | delay p50 / p90 (ms) | cost (us/frame) | cost / paper |")
    click.echo("|---|---|---|---|---|---|---|---|---|")
    paper_us = res["paper"].us_per_frame if "paper" in res else float("nan")
    for name, r in res.items():
        s = r.score
        click.echo(f"| {name} | {s.events} | {s.found} | {s.f1:.3f} | {s.false_alarms} ({s.false_alarms_per_hour:.1f}) | "
                   f"{s.vf_as_slip} | {_delays(s)} | {r.us_per_frame:.1f} | {_num(r.us_per_frame / paper_us, 'x')} |")
        if per_scene:
            for scene, ss in r.per_scene.items():
                click.echo(f"|   {scene} | {ss.events} | {ss.found} | {ss.f1:.3f} | {ss.false_alarms} | {ss.vf_as_slip} | "
                           f"{_delays(ss)} | | |")
    for path, (total, scenes_) in (bound or {}).items():
        rows = [(oracle_label(settings, path), total)] + ([(f"  {sc}", ss) for sc, ss in scenes_.items()]
                                                          if per_scene else [])
        for label, ss in rows:
            click.echo(f"| {label} | {ss.events} | {ss.found} | - | - | - | {_delays(ss)} | | |")
    _stability_table(res, per_scene)
    for name, r in res.items():
        _unseen_line(name, r.score)
        if per_scene:
            for scene, ss in r.per_scene.items():
                _unseen_line(f"{name}, {scene}", ss)
        if within_ms:
            shares = ", ".join(f"{_within(r.score, ms):.0f} % within {ms} ms" for ms in within_ms)
            click.echo(f"# {name}: of {r.score.events} slip events, {shares}")
    for path, (total, _) in (bound or {}).items() if within_ms else ():
        shares = ", ".join(f"{_within(total, ms):.0f} % within {ms} ms" for ms in within_ms)
        click.echo(f"# {oracle_label(settings, path)}: of {total.events} slip events, {shares}")


def oracle_key(path: str) -> str:
    """An oracle's key in --format json, by what it watches (evaluation/bound.py's PATHS)."""
    return "oracle" if path == "cof" else f"oracle_{path}"


def oracle_label(settings: Any, path: str = "cof") -> str:
    watches = "" if path == "cof" else ", whole distribution"
    return f"oracle{watches} (knows onset and path, z {settings.cof_track.ramp_z:g})"


def _oracle(scenes: tuple[str, ...], seeds: tuple[int, ...], rate_hz: float, settings: Any, hook: Any,
            stream: int | None = None) -> dict[str, tuple[Any, dict[str, Any]]]:
    """The bound's delays (evaluation/bound.py) at the ramp channel's threshold, for
    each oracle: the one watching the centre of force, the one watching the distribution."""
    from ..evaluation.bound import oracle_score

    with Ticker(len(scenes) * len(seeds), "oracle") as ticker:
        return oracle_score(scenes, seeds, settings.cof_track.ramp_z, rate_hz, hook, stream, progress=ticker)


def _oracle_json(total: Any, per_scene: dict[str, Any], settings: Any, within_ms: tuple[int, ...]) -> dict[str, Any]:
    def one(s: Any) -> dict[str, Any]:
        return {"events": s.events, "found": s.found, "delay_p50_ms": s.delay_percentile(50) * 1000,
                "delay_p90_ms": s.delay_percentile(90) * 1000}
    return {"z": settings.cof_track.ramp_z, **one(total), "within_ms": {str(ms): _within(total, ms) for ms in within_ms},
            "per_scene": {sc: one(ss) for sc, ss in per_scene.items()}}


def _families(methods: tuple[str, ...], scenes: tuple[str, ...], seeds: str, rate_hz: float, tolerance_s: float,
              long_holds: bool, profile_path: str | None, per_family_: bool, family_opt: tuple[str, ...],
              hold_out: tuple[str, ...], fmt: str, per_scene: bool, within_ms: tuple[int, ...],
              conditions: tuple[str, ...] = (), oracle: bool = False) -> None:
    if scenes or long_holds:
        raise click.UsageError("--per-family and --hold-out-family take the families' scenes; leave out "
                               "--scene and --long-holds")
    settings = open_profile(profile_path).detector if profile_path else DEFAULT_SETTINGS
    if hold_out:
        if seeds != "evaluation":
            raise click.UsageError("--hold-out-family chooses on the tuning seeds and reports on the held-out "
                                   "ones (evaluation/corpus.py); leave out --seeds")
        if len(methods) > 1:
            raise click.UsageError("--hold-out-family chooses the setting of one method: give at most one -m")
        if conditions or oracle:
            raise click.UsageError("--hold-out-family takes the families as they are: leave out --condition and --oracle")
        leave_one_out(methods[0] if methods else settings.method, family_names(hold_out), rate_hz, settings,
                      tolerance_s, fmt, _figures, _delays)
        return
    families = family_names(family_opt or ("all",))  # (a misspelt family is refused before any training)
    names = methods or detector_names()
    if "learned" in names:
        names = _prepare_learned(names)
    shares = (lambda s: ", ".join(f"{_within(s, ms):.0f} % within {ms} ms" for ms in within_ms)) if within_ms else None
    per_family(names, families, seeds, _seeds(seeds), rate_hz, settings, tolerance_s,
               fmt, _figures, _delays, per_scene, shares, _conditions(conditions), conditions,
               (lambda scenes, seed_set, hook, stream: _oracle(scenes, seed_set, rate_hz, settings, hook, stream))
               if oracle else None, lambda path: (oracle_key(path), oracle_label(settings, path)))


def _figures(s: Any) -> dict[str, Any]:
    return {"events": s.events, "found": s.found, "f1": s.f1, "false_alarms": s.false_alarms,
            "false_alarms_per_hour": s.false_alarms_per_hour, "holding_s": s.holding_s,
            "varying_force_as_slip": s.vf_as_slip, "delay_p50_ms": s.delay_percentile(50) * 1000,
            "delay_p90_ms": s.delay_percentile(90) * 1000,
            # how steady the state is (the second table)
            "vf_episodes": s.vf_episodes, "vf_found": s.vf_found, "vf_recall": s.vf_recall,
            "vf_coverage": s.vf_coverage if s.vf_coverages else None,
            "vf_changes_per_episode_max": max(s.vf_episode_changes) if s.vf_episode_changes else None,
            "vf_changes_per_min": s.vf_changes_per_min, "still_changes_per_min": s.still_changes_per_min,
            "slip_episodes_per_event_max": max(s.slip_episodes) if s.slip_episodes else None,
            "slip_episodes_per_event_mean": float(np.mean(s.slip_episodes)) if s.slip_episodes else None,
            # a turn the detector said it could not see (TURN_UNSEEN; evaluation/metrics.py)
            "missed_turn_unseen": s.missed_unseen, "turn_unseen_share": s.unseen_share}


def _json_row(r: Any, res: dict[str, Any], within_ms: tuple[int, ...]) -> dict[str, Any]:
    paper_us = res["paper"].us_per_frame if "paper" in res else float("nan")
    return {"method": r.method, **_figures(r.score), "us_per_frame": r.us_per_frame,
            "cost_vs_paper": r.us_per_frame / paper_us,
            "within_ms": {str(ms): _within(r.score, ms) for ms in within_ms},
            "per_scene": {scene: _figures(ss) for scene, ss in r.per_scene.items()}}


def _conditions(items: tuple[str, ...]) -> Any:
    """One scene hook from NAME=VALUE items (the failure map's conditions, but the rate)."""
    from ..evaluation.conditions import CONDITIONS, MORE_CONDITIONS

    every = {**CONDITIONS, **MORE_CONDITIONS}
    hooks = []
    for item in items:
        name, _, value = item.partition("=")
        entry = every.get(name)
        if entry is None or entry[2] is None:
            known = ", ".join(n for n, c in every.items() if c[2] is not None)
            raise click.BadParameter(f"{item!r}: expected NAME=VALUE with NAME one of {known} (the rate is --rate)",
                                     param_hint="--condition")
        try:
            hooks.append(entry[2](float(value)))
        except ValueError:
            raise click.BadParameter(f"{item!r}: expected a number after '='", param_hint="--condition") from None
    if not hooks:
        return None

    def hook(spec: Any) -> Any:
        for h in hooks:
            spec = h(spec)
        return spec

    return hook


def _unseen_line(label: str, s: Any) -> None:
    """Where the method said a turn would read stable (TURN_UNSEEN; cof-track only)."""
    if s.unseen_s > 0 or s.missed_unseen:
        click.echo(f"# {label}: of {s.events - s.found} missed slip events, {s.missed_unseen} flagged TURN_UNSEEN "
                   f"throughout; TURN_UNSEEN in effect {_num(100 * s.unseen_share, ' %')} of the holding time")


def _stability_table(res: dict[str, Any], per_scene: bool) -> None:
    """The second table: how steady the reported state is (evaluation/metrics.py)."""
    click.echo("")
    click.echo("| method | varying-force episodes | found (recall) | coverage after 150 ms: pooled / worst / episodes >= 90 % "
               "| state changes per episode: mean / max | changes per min in varying force | "
               "changes per min in still holds (min held) | varying force entered after onset, p50 / p90 (ms) "
               "| left after its end | slip left after its end | slip episodes per found event: mean / max |")
    click.echo("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, r in res.items():
        rows = [(name, r.score)] + ([(f"  {scene}", ss) for scene, ss in r.per_scene.items()] if per_scene else [])
        for label, s in rows:
            click.echo(f"| {label} | {_stability(s)} |")


def _stability(s: Any) -> str:
    ch = s.vf_episode_changes
    cov = s.vf_coverages
    coverage = (f"{_num(100 * s.vf_coverage, ' %', 0)} / {_num(100 * min(cov), ' %', 0)} / "
                f"{_num(100 * s.vf_covered_share(0.9), ' %', 0)}") if cov else "- / - / -"
    changes = f"{np.mean(ch):.1f} / {max(ch)}" if ch else "- / -"
    return (f"{s.vf_episodes} | {s.vf_found} ({_num(s.vf_recall, '', 2)}) | {coverage} | {changes} | "
            f"{_num(s.vf_changes_per_min)} | {_num(s.still_changes_per_min, '', 2)} ({s.still_s / 60:.1f}) | "
            f"{_ms(s.vf_entry_s)} | {_ms(s.vf_exit_s)} | {_ms(s.slip_exit_s)} | {slip_episodes(s.slip_episodes)}")


def _ms(values: list[float]) -> str:
    """p50 / p90 of some delays, in ms."""
    p = [np.percentile(values, q) * 1000 for q in (50, 90)] if values else [math.nan, math.nan]
    return f"{_num(p[0], digits=0)} / {_num(p[1], digits=0)}"


def _num(value: float, unit: str = "", digits: int = 1) -> str:
    """A figure, or '-' where there is none (no slip found, no paper in the run)."""
    return f"{value:.{digits}f}{unit}" if math.isfinite(value) else "-"


def _delays(score: Any) -> str:
    return f"{_num(score.delay_percentile(50) * 1000, digits=0)} / {_num(score.delay_percentile(90) * 1000, digits=0)}"


def _within(score: Any, ms: int) -> float:
    """Percent of all slip events flagged at most ``ms`` after onset (a missed one never is)."""
    # (a small tolerance: delays are differences of frame times, ms a whole number)
    hits = sum(1 for d in score.delays_s if d * 1000.0 <= ms + 1e-6)
    return 100.0 * hits / score.events if score.events else float("nan")


def _prepare_learned(names: tuple[str, ...]) -> tuple[str, ...]:
    """Read the learned method's shipped model up front, so that a missing or damaged
    file is one line before any scene is scored (the model is trained on the tuning
    seeds by scripts/train-learned, never here)."""
    from ..models import default_model

    default_model()
    return names
