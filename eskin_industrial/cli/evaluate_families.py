"""``eskin-bus evaluate --families / --per-family / --hold-out-family``: the effect
families (``evaluation/families.py``) and leave-one-family-out (``evaluation/holdout.py``)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import click

from ..detect.settings import DetectorSettings
from ..evaluation.families import FAMILIES, evaluate_families, family_hook
from ..evaluation.holdout import CANDIDATES, FALSE_ALARMS_PER_HOUR, hold_out, tuning_scores
from ..evaluation.metrics import SceneScore
from ..evaluation.suite import TUNING_SEEDS, by_name
from ..progress import Prefixed
from .console import Ticker, echo_json


def family_names(given: tuple[str, ...]) -> tuple[str, ...]:
    """Family names as given ('all': every family; 'new': the new physics), checked."""
    out: list[str] = []
    for name in given:
        if name == "all":
            out += list(FAMILIES)
        elif name == "new":
            out += [f for f, fam in FAMILIES.items() if not fam.in_suite]
        elif name in FAMILIES:
            out.append(name)
        else:
            raise click.BadParameter(f"unknown family {name!r}; families: all, new, {', '.join(FAMILIES)} "
                                     "(eskin-bus evaluate --families)", param_hint="'--family' / '--hold-out-family'")
    return tuple(dict.fromkeys(out))


def list_families() -> None:
    click.echo("| family | in the suite | scenes | what |")
    click.echo("|---|---|---|---|")
    for f in FAMILIES.values():
        click.echo(f"| {f.name} | {'yes' if f.in_suite else 'new'} | {', '.join(f.scenes)} | {f.description} |")


def _row(s: Any, delays: Callable[[Any], str]) -> str:
    return (f"{s.events} | {s.found} | {s.f1:.3f} | {s.false_alarms} ({s.false_alarms_per_hour:.1f}) | "
            f"{s.vf_as_slip} | {delays(s)}")


def slip_episodes(per_event: list[int]) -> str:
    """Slip episodes per found slip event, mean / max (1 / 1: no slip flickered)."""
    return f"{sum(per_event) / len(per_event):.2f} / {max(per_event)}" if per_event else "- / -"


def per_family(names: tuple[str, ...], families: tuple[str, ...], seeds: str, seed_set: tuple[int, ...],
               rate_hz: float, settings: DetectorSettings, tolerance_s: float, fmt: str,
               figures: Callable[[Any], dict[str, Any]], delays: Callable[[Any], str], per_scene: bool = False,
               within: Callable[[Any], str] | None = None, spec_hook: Any = None, conditions: tuple[str, ...] = (),
               oracle: Callable[..., Any] | None = None,
               oracle_names: Callable[[str], tuple[str, str]] = lambda path: (path, path)) -> None:
    """``oracle(scenes, seeds, hook, stream)`` gives each oracle's bound by its path;
    ``oracle_names(path)`` its JSON key and row label."""
    start = time.perf_counter()
    with Ticker(sum(len(FAMILIES[f].scenes) for f in families) * len(seed_set) * len(names), "scoring") as ticker:
        res = evaluate_families(by_name(*names), families, seed_set, rate_hz, settings, tolerance_s,
                                progress=ticker, spec_hook=spec_hook)
    # the bound per family (evaluation/bound.py): the oracle's delays on the same scenes
    bounds = {f: oracle(FAMILIES[f].scenes, seed_set, family_hook(FAMILIES[f], spec_hook), FAMILIES[f].stream)
              for f in families} if oracle is not None else {}
    if fmt == "json":
        def bound(total: Any, scenes: dict[str, Any]) -> dict[str, Any]:
            one = lambda s: {"events": s.events, "found": s.found, "delay_p50_ms": s.delay_percentile(50) * 1000,  # noqa: E731
                             "delay_p90_ms": s.delay_percentile(90) * 1000}
            return {**one(total), "per_scene": {sc: one(ss) for sc, ss in scenes.items()}}
        oracles: dict[str, dict[str, Any]] = {}  # each oracle's key: its bound per family
        for f, by_path in bounds.items():
            for path, b in by_path.items():
                oracles.setdefault(oracle_names(path)[0], {})[f] = bound(*b)
        echo_json({"seeds": seeds, "seed_list": list(seed_set), "rate_hz": rate_hz, "conditions": list(conditions),
                   "families": {f: {m: {**figures(r.score),
                                        "per_scene": {sc: figures(ss) for sc, ss in r.per_scene.items()}}
                                    for m, r in by.items()} for f, by in res.items()},
                   **oracles})
        return
    click.echo(f"# eskin-bus evaluate --per-family --seeds {seeds} --rate {rate_hz:g}"
               + "".join(f" --condition {c}" for c in conditions) + "  "
               f"({len(families)} families x {len(seed_set)} seeds, {time.perf_counter() - start:.0f} s)")
    click.echo("| family | method | events | found | F1 | false alarms (per h holding) | varying force as slip | "
               "delay p50 / p90 (ms) | slip episodes per found event: mean / max |")
    click.echo("|---|---|---|---|---|---|---|---|---|")
    for fam, by in res.items():
        for m, r in by.items():
            click.echo(f"| {fam} | {m} | {_row(r.score, delays)} | {slip_episodes(r.score.slip_episodes)} |")
            if per_scene:
                for scene, ss in r.per_scene.items():
                    click.echo(f"|   | {scene} | {_row(ss, delays)} | {slip_episodes(ss.slip_episodes)} |")
        for path, (total, scenes) in bounds.get(fam, {}).items():
            rows = [(f"{fam} | {oracle_names(path)[1]}", total)] + (
                [(f"  | {sc}", ss) for sc, ss in scenes.items()] if per_scene else [])
            for label, ss in rows:
                click.echo(f"| {label} | {ss.events} | {ss.found} | - | - | - | {delays(ss)} | - |")
    if within is not None:
        for fam, by in res.items():
            for m, r in by.items():
                click.echo(f"# {fam}, {m}: {within(r.score)}")


def leave_one_out(method: str, families: tuple[str, ...], rate_hz: float, settings: DetectorSettings,
                  tolerance_s: float, fmt: str, figures: Callable[[Any], dict[str, Any]],
                  delays: Callable[[Any], str]) -> None:
    if method not in CANDIDATES:
        raise click.UsageError(f"--hold-out-family chooses among candidate settings of the deciding method; "
                               f"{method!r} has none (methods with some: {', '.join(CANDIDATES)})")
    start = time.perf_counter()
    with Ticker(sum(len(f.scenes) for f in FAMILIES.values()) * len(TUNING_SEEDS) * len(CANDIDATES[method]),
                f"choosing {method}") as ticker:
        tuning = tuning_scores(method, settings, rate_hz, tolerance_s=tolerance_s, progress=Prefixed(ticker, "tuning "))
        results = [hold_out(method, fam, tuning, settings, rate_hz, tolerance_s=tolerance_s,
                            progress=Prefixed(ticker, "held out ")) for fam in families]
    if fmt == "json":
        echo_json({"method": method, "rate_hz": rate_hz, "candidates": [c.label for c in CANDIDATES[method]],
                   "false_alarm_target_per_h": FALSE_ALARMS_PER_HOUR,
                   "tuning": {f: {c: figures(s) for c, s in by.items()} for f, by in tuning.items()},
                   "hold_outs": [{"family": h.family, "chosen": h.chosen, "tuning": figures(h.tuning),
                                  "held_out": figures(h.held_out), "default": figures(h.default)} for h in results]})
        return
    click.echo(f"# leave-one-family-out, {method}: chosen among {len(CANDIDATES[method])} candidates "
               f"({'; '.join(c.label for c in CANDIDATES[method])}) on the tuning seeds of the other families, "
               f"reported on the held-out family's evaluation seeds ({time.perf_counter() - start:.0f} s)")
    click.echo(f"# each candidate on the tuning seeds {','.join(map(str, TUNING_SEEDS))} of all families "
               "(each hold-out pools all but its own)")
    click.echo("| candidate | events | found | F1 | false alarms (per h holding) | varying force as slip | "
               "delay p50 / p90 (ms) |")
    click.echo("|---|---|---|---|---|---|---|")
    for c in CANDIDATES[method]:
        pooled = SceneScore()
        for by in tuning.values():
            pooled += by[c.label]
        click.echo(f"| {c.label} | {_row(pooled, delays)} |")
    click.echo("| held-out family | chosen | tuning, other families: F1, false alarms per h, p50 (ms) | "
               "held out, chosen: events | found | F1 | false alarms (per h) | varying force as slip | "
               "delay p50 / p90 (ms) | held out, default: found, F1, p50 / p90 |")
    click.echo("|---|---|---|---|---|---|---|---|---|---|")
    for h in results:
        t, d = h.tuning, h.default
        click.echo(f"| {h.family} | {h.chosen} | {t.f1:.3f}, {t.false_alarms_per_hour:.2f}, "
                   f"{delays(t).split(' / ')[0]} | {_row(h.held_out, delays)} | {d.found}, {d.f1:.3f}, {delays(d)} |")
