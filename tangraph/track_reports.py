"""A track for a person and as data: :func:`dead_reckoning_track` (the baseline every estimator
must beat), :func:`track_report` (the figures of ``tangraph navigate/smooth --json``) and
:func:`track_summary` (the text the CLI and the demo print). Re-exported by
:mod:`tangraph.navigation`."""

from __future__ import annotations

import numpy as np

from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["dead_reckoning_track", "track_report", "track_summary"]


def dead_reckoning_track(survey: Survey) -> Track:
    """The dead-reckoned poses as a track (no covariance): the baseline."""
    return Track(time=survey.time, pose=survey.dr_pose, method="dr")


def track_report(track: Track, survey: Survey) -> dict:
    """The figures of a track, as data (``tangraph navigate/smooth --json``): poses, fixes by
    outcome (graph and fix-based filters), divergences, run time, and the errors against the
    survey's reference track (with the dead reckoning's) where it has one."""
    report: dict = {"method": track.method, "poses": track.n_poses,
                    "duration_s": float(track.time[-1] - track.time[0])}
    meta = track.meta
    if track.fixes is not None:
        outcomes: dict[str, int] = {}
        for fix in track.fixes:  # FixRecords, of the graph and the fix-based filters alike
            outcomes[fix.status.value] = outcomes.get(fix.status.value, 0) + 1
        report["fixes"] = {"accepted": int(meta.get("n_fixes_accepted", 0)),
                           "rejected": int(meta.get("n_fixes_rejected", 0)),
                           "by_outcome": dict(sorted(outcomes.items(), key=lambda kv: -kv[1]))}
    if "soundings" in meta:  # the smoother on every sounding
        counts = ("soundings", "soundings_used", "field_nodes", "pings_left_out")
        report["soundings"] = {k: int(v) if k in counts else float(v) for k, v in meta["soundings"].items()}
    if "n_divergences" in meta:
        report["divergences"] = int(meta["n_divergences"])
    if "lost_steps" in meta:
        report["lost"] = {"pings": int(track.lost.sum()), "episodes": len(meta.get("lost_episodes", [])),
                          "off_map_pings": int(meta.get("n_off_map", 0))}
    if "start_prior" in meta:
        report["start_prior"] = meta["start_prior"]
    if track.timings:
        report["run_time_s"] = float(track.timings.get("total", float("nan")))
        report["per_step_s"] = float(track.timings.get("per_step", float("nan")))
    if "calibration" in meta:
        report["calibration"] = {k: float(v) for k, v in meta["calibration"].items()}
    if survey.true_pose is not None:
        from tangraph.eval.metrics import track_metrics

        keys = ("rmse", "median_error", "final_error", "max_error", "anees", "final_nees")
        m = track_metrics(track, survey.true_pose)
        d = track_metrics(dead_reckoning_track(survey), survey.true_pose)
        report["reference"] = survey.meta.get("reference", "truth")
        report["error"] = {k: m[k] for k in keys}
        report["dead_reckoning_error"] = {k: d[k] for k in keys[:4]}
    return report


def track_summary(track: Track, survey: Survey) -> str:
    """A few lines on a track for a person: :func:`track_report` as text."""
    r = track_report(track, survey)
    lines = [f"method       {r['method']}: {r['poses']} poses over {r['duration_s']:.1f} s"]
    if "fixes" in r:
        detail = ", ".join(f"{n} {k}" for k, n in r["fixes"]["by_outcome"].items())
        lines.append(f"fixes        {r['fixes']['accepted']} accepted, {r['fixes']['rejected']} "
                     f"rejected ({detail})")
    if "soundings" in r:
        snd = r["soundings"]
        left = snd.get("pings_left_out", 0)
        by = f"the gate, and the {left} pings where windows found several places" if left else "the gate"
        lines.append(f"soundings    {snd['soundings_used']} of {snd['soundings']} weighed (the others left "
                     f"out by {by}), tide {snd['tide']:+.2f} m, variances x {snd['variance_factor']:.2f}^2")
        if "field_factor" in snd:
            lines.append(f"map error    estimated with the track on {snd['field_nodes']} nodes "
                         f"{snd['field_spacing']:.0f} m apart, its stated std x {snd['field_factor']:.2f} "
                         f"(in patches up to x {snd.get('field_factor_max', snd['field_factor']):.2f}), "
                         f"correction RMS {snd['field_rms']:.2f} m")
        if "map_offset" in snd:
            (n, e), (sn, se) = snd["map_offset"], snd["map_offset_std"]
            lines.append(f"map offset   the map lies {n:+.2f} +- {sn:.2f} m north, {e:+.2f} +- {se:.2f} m "
                         "east of where its coordinates say")
    if "divergences" in r:
        lines.append(f"divergences  {r['divergences']} (re-initialised from dead reckoning)")
    if r.get("lost", {}).get("pings"):
        lost = r["lost"]
        episodes = f" in {lost['episodes']} episodes" if lost["episodes"] else ""
        lines.append(f"lost         {lost['pings']} pings flagged lost{episodes} (column 'lost' of the "
                     "track: their poses are not to be trusted)")
    if r.get("lost", {}).get("off_map_pings"):
        lines.append(f"off the map  {r['lost']['off_map_pings']} pings: dead reckoning only there")
    if r.get("start_prior") == "outlier":
        lines.append("start        the start position prior disagreed with the fixes and was dropped")
    if "run_time_s" in r:
        lines.append(f"run time     {r['run_time_s']:.2f} s in all, {1e3 * r['per_step_s']:.2f} ms per step")
    if "error" in r:
        m, d = r["error"], r["dead_reckoning_error"]
        lines.append(
            f"error        RMSE {m['rmse']:.2f} m, median {m['median_error']:.2f} m, "
            f"final {m['final_error']:.2f} m, max {m['max_error']:.2f} m against the {r['reference']} "
            f"(dead reckoning: RMSE {d['rmse']:.2f} m, median {d['median_error']:.2f} m, "
            f"final {d['final_error']:.2f} m)"
        )
        if np.isfinite(m["anees"]):
            lines.append(f"consistency  ANEES {m['anees']:.2f} (2 for an honest covariance)")
    return "\n".join(lines)
