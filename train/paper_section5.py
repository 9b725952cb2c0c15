"""The paper's §5 beside ours: ``python -m train.paper_section5 DIR`` reads an ``nbs compare`` output
on ``five_rooms`` and prints the tables of docs/results.md's "The paper's §5 against ours".

The paper (González-de Santos et al., "Autonomous Scanning of Structural Elements in Buildings",
§5) reports, on five concave rooms, its method against Stachniss & Burgard [12], Blaer & Allen [3]
and Potthast & Sukhatme [2]. Its numbers are transcribed in :data:`PAPER`, each with the sentence
it comes from; where the paper gives only a reduction, the other method's figure is derived from it
(marked ≈). The reductions are computed from our runs the way the paper states them:

- time: 1 − T(ours) / T(theirs), totals of processing + acquisition + travel;
- processed points: the mean over rooms of 1 − P(ours) / P(theirs);
- path: 1 − L(ours) / L(theirs) over the rooms the paper names (rooms 1-3 against S&B, rooms 1
  and 3 against P&S, all five against B&A, where the paper's is −2.8%: 2.8% more).

Our rooms are numbered in ``five_rooms``' order (living, hall, study, kitchen, lounge = #1-#5); the
paper's figure does not say which of its rooms is which, so per-room comparisons with it are not
made beyond the room sets above.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from train.compare import _cell, _mean_std, folder_name

__all__ = ["PAPER", "main", "tables"]

#: The methods, as ``nbs compare`` names them, and the paper's reference numbers.
METHODS = ("greedy", "stachniss_burgard", "blaer_allen", "potthast_sukhatme")
LABELS = {
    "greedy": "the paper's method (greedy NBS)",
    "stachniss_burgard": "Stachniss & Burgard [12]",
    "blaer_allen": "Blaer & Allen [3]",
    "potthast_sukhatme": "Potthast & Sukhatme [2]",
}
_OURS_TIME = 14868.0
#: What §5 states. Keys: scans, time_s, se_pct, points, path_m, rooms_done; "…_note" says where
#: a figure covers fewer rooms or is derived.
PAPER: dict[str, dict[str, Any]] = {
    "greedy": {
        "scans": 22, "time_s": _OURS_TIME, "se_pct": 88.57, "points": 23_576_419, "path_m": 88.26,
        "rooms_done": "5/5",
    },
    "stachniss_burgard": {
        "time_s": _OURS_TIME / (1 - 0.336), "time_note": "≈, from −33.6%", "se_pct": 84.3,
        "se_note": "rooms 1-3", "path_m": 62.28, "path_note": "rooms 1-3", "rooms_done": "3/5",
    },
    "blaer_allen": {
        "scans": 25, "time_s": _OURS_TIME / (1 - 0.837), "time_note": "≈, from −83.7%", "se_pct": 87.26,
        "se_note": "cited as [4]", "path_m": 85.82, "rooms_done": "5/5",
    },
    "potthast_sukhatme": {
        "time_s": _OURS_TIME / (1 - 0.787), "time_note": "≈, from −78.7%", "se_pct": 87.0,
        "se_note": "rooms 1-3", "path_m": 43.82, "path_note": "rooms 1 and 3", "rooms_done": "3/5",
    },
}  # fmt: skip
#: The reductions §5 states against each method: (time, processed points, path, path's rooms).
PAPER_REDUCTIONS = {
    "stachniss_burgard": (33.6, 7.2, 30.0, (0, 1, 2)),
    "blaer_allen": (83.7, 23.0, -2.8, (0, 1, 2, 3, 4)),
    "potthast_sukhatme": (78.7, 14.0, 25.0, (0, 2)),
}


def _runs(folder: Path, policy: str) -> list[dict[str, Any]]:
    base = folder / "runs" / "five_rooms" / folder_name(policy)
    return [json.loads(p.read_text()) for p in sorted(base.glob("seed*/metrics.json"))]


def _room_times(m: dict[str, Any]) -> np.ndarray:
    """(rooms,) total time per room: its processing, and acquisition and travel shared out by its
    points and its path."""
    rooms = m["rooms"]
    points = np.array([sum(s["points"] for s in m["steps"] if s["room"] == r["id"]) for r in rooms], float)
    path = np.array([r["path_length_m"] for r in rooms], float)
    acq = m["acquisition_time_s"] * points / max(1.0, points.sum())
    travel = m["travel_time_s"] * path / max(1e-9, path.sum())
    return np.array([r["processing_time_s"] for r in rooms]) + acq + travel


def _per_run(m: dict[str, Any]) -> dict[str, Any]:
    rooms = m["rooms"]
    ends = {e["room"]: e["reason"] for e in m.get("room_ends", [])}
    return {
        "scans": m["scans"],
        "time_s": m["processing_time_s"] + m["acquisition_time_s"] + m["travel_time_s"],
        "se_pct": m["structure_sensed_pct"],
        "points": m["processed_points"],
        "path_m": m["path_length_m"],
        "room_scans": np.array([r["scans"] for r in rooms], float),
        "room_time": _room_times(m),
        "room_se": np.array([r["structure_sensed_pct"] for r in rooms], float),
        "room_points": np.array([r["processed_points"] for r in rooms], float),
        "room_path": np.array([r["path_length_m"] for r in rooms], float),
        "cap_ended": sum(1 for reason in ends.values() if reason == "cap"),
        "ends": len(ends),
        "names": [r["name"] for r in rooms],
    }


def _ms(values: Sequence[float], fmt: str) -> str:
    """``mean ± std`` over seeds, as ``nbs compare``'s tables write it."""
    return _cell(_mean_std(values), fmt)


def tables(folder: str | Path, controlled: bool = False) -> str:
    """The markdown of docs/results.md's §5 tables from an ``nbs compare`` output folder."""
    folder = Path(folder)
    runs = {p: [_per_run(m) for m in _runs(folder, p)] for p in METHODS}
    missing = [p for p, r in runs.items() if not r]
    if missing:
        raise FileNotFoundError(f"{folder}: no five_rooms runs of {', '.join(missing)}")
    seeds = len(runs["greedy"])
    out = [f"Totals ({seeds} seeds, mean ± std; the paper's figures in the rows marked *paper*):", ""]
    out += ["| method | | scans | time (s) | SE sensed (%) | processed points | path (m) | rooms ended by the cap |",
            "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for p in METHODS:
        paper = PAPER[p]

        def cell(key: str, fmt: str, paper=paper) -> str:
            if key not in paper:
                return "–"
            note = paper.get(key.split("_")[0] + "_note")
            return fmt.format(paper[key]) + (f" ({note})" if note else "")

        out.append(
            f"| {LABELS[p]} | *paper* | {cell('scans', '{}')} | {cell('time_s', '{:,.0f}')} "
            f"| {cell('se_pct', '{:.2f}')} "
            f"| {cell('points', '{:,}')} | {cell('path_m', '{:.2f}')} | rooms completed {paper['rooms_done']} |"
        )
        r = runs[p]
        cap = sum(x["cap_ended"] for x in r)
        out.append(
            f"| | ours | {_ms([x['scans'] for x in r], '{:.1f}')} | {_ms([x['time_s'] for x in r], '{:,.0f}')} "
            f"| {_ms([x['se_pct'] for x in r], '{:.1f}')} | {_ms([x['points'] for x in r], '{:,.0f}')} "
            f"| {_ms([x['path_m'] for x in r], '{:.1f}')} | {cap} of {sum(x['ends'] for x in r)} |"
        )
    greedy = runs["greedy"]
    out += [
        "",
        "Reductions of the paper's method against each (the paper's; ours, computed the same way "
        "from each seed's runs):",
        "",
    ]
    out += ["| against | time: paper | ours | processed points (mean over rooms): paper | ours | path: paper "
            "| ours | path's rooms |", "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for p, (t_paper, pts_paper, path_paper, rooms) in PAPER_REDUCTIONS.items():
        pairs = list(zip(greedy, runs[p], strict=False))
        t = [100 * (1 - g["time_s"] / o["time_s"]) for g, o in pairs]
        pts = [100 * np.mean(1 - g["room_points"] / np.maximum(o["room_points"], 1)) for g, o in pairs]
        idx = list(rooms)
        path = [100 * (1 - g["room_path"][idx].sum() / max(o["room_path"][idx].sum(), 1e-9)) for g, o in pairs]
        names = ", ".join(f"#{k + 1}" for k in idx)
        out.append(
            f"| {LABELS[p]} | {t_paper:.1f}% | {_ms(t, '{:.1f}')}% | {pts_paper:.1f}% | {_ms(pts, '{:.1f}')}% "
            f"| {path_paper:.1f}% | {_ms(path, '{:.1f}')}% | {names} |"
        )
    names = greedy[0]["names"]
    out += ["", "Per room, ours (mean over seeds; rooms #1-#5 = " + ", ".join(names) + "):", ""]
    out += ["| method | room | scans | time (s) | SE sensed (%) | processed points | path (m) |",
            "|---|---|---|---|---|---|---|"]  # fmt: skip
    for p in METHODS:
        r = runs[p]
        for k, name in enumerate(names):
            out.append(
                f"| {LABELS[p] if k == 0 else ''} | #{k + 1} {name} | {np.mean([x['room_scans'][k] for x in r]):.1f} "
                f"| {np.mean([x['room_time'][k] for x in r]):,.0f} | {np.mean([x['room_se'][k] for x in r]):.1f} "
                f"| {np.mean([x['room_points'][k] for x in r]):,.0f} | {np.mean([x['room_path'][k] for x in r]):.1f} |"
            )
    if controlled:
        out += [
            "",
            "The controlled mode (every method ends rooms by the greedy's rule; it only chooses where to scan):",
            "",
        ]
        out += ["| method | scans | time (s) | SE sensed (%) | processed points | path (m) |",
                "|---|---|---|---|---|---|"]  # fmt: skip
        for p in METHODS:
            name = p if p == "greedy" else f"{p}:controlled"
            r = [_per_run(m) for m in _runs(folder, name)]
            if not r:
                raise FileNotFoundError(f"{folder}: no five_rooms runs of {name}")
            out.append(
                f"| {name} | {_ms([x['scans'] for x in r], '{:.1f}')} | {_ms([x['time_s'] for x in r], '{:,.0f}')} "
                f"| {_ms([x['se_pct'] for x in r], '{:.1f}')} | {_ms([x['points'] for x in r], '{:,.0f}')} "
                f"| {_ms([x['path_m'] for x in r], '{:.1f}')} |"
            )
    return "\n".join(out) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m train.paper_section5", description=__doc__.splitlines()[0])
    p.add_argument("folder", help="an nbs compare --out folder with five_rooms runs of the four methods")
    p.add_argument("--controlled", action="store_true", help="add the controlled mode's table (X:controlled runs)")
    args = p.parse_args(argv)
    try:
        print(tables(args.folder, args.controlled), end="")
    except (FileNotFoundError, KeyError, ValueError) as exc:
        print(f"paper_section5: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
