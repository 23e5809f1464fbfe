"""What a replication's free-driving episodes (chapter 09's Fig. 5 analogue) record, summarised per method.

``results.json``'s ``free_driving`` holds, per method, its first-seed agent's episodes from fixed
starts with no time limit on the route: each episode's result, its share of the road lanes covered
and its ``visits`` (per junction pass, the approach and the exit taken).
"""

from __future__ import annotations

from ibc_tutorial import stats
from ibc_tutorial.driving.analysis import exit_counts


def pooled_visits(free_driving: dict, methods) -> dict[str, list]:
    """method -> every junction pass of its free-driving episodes, in episode order."""
    return {m: [v for e in free_driving[m]["episodes"] for v in e["visits"]] for m in methods}


def format_free_driving(free_driving: dict, methods, still_m: float) -> str:
    """Two lines per method: junction passes and approaches, lane coverage (all episodes, and each
    alone), episodes that drove less than ``still_m`` metres, how each ended; then the visits at
    approaches seen twice or more that did not take the approach's most common exit."""
    visits = pooled_visits(free_driving, methods)
    lines = []
    for m in methods:
        episodes = free_driving[m]["episodes"]
        ends = [e["result"]["termination"] or "-" for e in episodes]
        short = sum(e["result"]["distance_m"] < still_m for e in episodes)
        minority, total = stats.exit_spread(visits[m])
        per_episode = [e["coverage"] for e in episodes]  # each episode alone
        lines.append(
            f"{m:7s} {len(visits[m])} junction passes at {len(exit_counts(visits[m]))} approaches; coverage "
            f"{free_driving[m]['coverage_all']:.2f} (each episode alone {min(per_episode):.2f} to "
            f"{max(per_episode):.2f}); episodes standing still: {short}; ends: {' '.join(ends)}"
        )
        lines.append(
            f"        at approaches visited twice or more: {minority} of {total} visits "
            f"not by the approach's most common exit"
        )
    return "\n".join(lines)
