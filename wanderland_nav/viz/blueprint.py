"""The default rerun layout: the 3D scene on the left; the agent's camera and the plots on the right.

Sent with the recording (`RecordingStream.save(path, default_blueprint=...)`), so a researcher who
opens the `.rrd` sees the useful views without arranging panels by hand.
"""

from __future__ import annotations

import rerun.blueprint as rrb


def default_blueprint(*, agent: int = 0, camera: bool = True, plots: bool = True,
                      training: bool = False) -> rrb.Blueprint:
    """agent: whose camera is shown; training: add the loss / eval-curve panels of `RerunLogger`."""
    right = []
    if camera:
        right.append(rrb.Spatial2DView(origin=f"world/agents/agent_{agent}/camera", name=f"agent {agent} camera"))
    if plots:
        right.append(rrb.Tabs(
            rrb.TimeSeriesView(origin="plots/distance_to_goal", name="distance to goal"),
            rrb.TimeSeriesView(origin="plots/reward", name="reward"),
            rrb.TimeSeriesView(origin="plots/metrics", name="episode metrics"),
        ))
    if training:
        right.append(rrb.Tabs(
            rrb.TimeSeriesView(origin="eval", name="eval NE/SR/SPL/IR"),
            rrb.TimeSeriesView(origin="losses", name="losses"),
            rrb.TimeSeriesView(origin="train", name="train"),
            rrb.TimeSeriesView(origin="bc", name="behaviour cloning"),
            rrb.TimeSeriesView(origin="rollouts", name="rollout rewards / distances"),
            rrb.TimeSeriesView(origin="time", name="time"),
        ))
    main = rrb.Spatial3DView(origin="world", name="scene")
    layout = rrb.Horizontal(main, rrb.Vertical(*right), column_shares=[3, 2]) if right else main
    return rrb.Blueprint(layout, rrb.TimePanel(state="collapsed"), collapse_panels=False)
