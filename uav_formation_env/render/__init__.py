"""Headless top-view renderer of a formation (matplotlib Agg) and GIF writing (Pillow).

:class:`TopViewRenderer` builds one :class:`matplotlib.figure.Figure` on a
:class:`~matplotlib.backends.backend_agg.FigureCanvasAgg` when it is created and only updates its
artists afterwards: a frame costs one Agg draw and touches no pyplot state.

What a frame shows (top view, x right, y up, equal aspect):

========================  =====================================================================
Element                   Drawing
========================  =====================================================================
UAV ``i``                 filled circle in the UAV's colour, numbered ``i`` (agent ``uav_i``)
trail                     the UAV's last ``trail_length`` positions, a thin line in its colour
obstacle                  filled disc of radius ``r`` in :data:`OBSTACLE_COLOR`
safety circle             dashed circle of radius ``R_s = r + safety_margin``
communication edge        line between sender ``j`` and receiver ``i`` of ``adjacency[i, j] != 0``,
                          coloured by sub-formation; only edges inside a group are drawn
reference velocity        arrow from the UAV, ``arrow_seconds`` seconds of travel long
collision                 red ring around every UAV flagged in ``collisions``
time                      ``t = ... s`` in the upper-left corner (and the collision count)
grid                      light lines at a world-fixed spacing of 1, 2 or 5 x 10^k m (about six
                          per view); the spacing and the view centre are printed under the time.
                          With ``show_ticks=True``: matplotlib axes with tick labels instead
========================  =====================================================================

The view is centred on the swarm and spans ``view_span`` m (wider with ``fit_swarm``).
:func:`render_episode` (:mod:`~uav_formation_env.render.episode`) writes an episode's frames as
a GIF, or an MP4 with the ``[video]`` extra (``uav-formation render``).
"""

from uav_formation_env.render.episode import render_episode
from uav_formation_env.render.gif import write_gif
from uav_formation_env.render.style import COLLISION_COLOR, OBSTACLE_COLOR, group_edges
from uav_formation_env.render.top_view import TopViewRenderer

__all__ = [
    "COLLISION_COLOR",
    "OBSTACLE_COLOR",
    "TopViewRenderer",
    "group_edges",
    "render_episode",
    "write_gif",
]
