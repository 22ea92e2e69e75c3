"""RViz markers of a landmark database's regions (``visualization_msgs/MarkerArray``).

One ``CUBE_LIST`` marker per region (namespace ``regions``, id = region index) holding
a flat square at each of its poses, in the region's colour, slightly raised by region
index so that overlapping regions stay visible; plus one ``SPHERE_LIST`` of the model
view positions (namespace ``model_views``). The builder publishes this on
``/builder/regions`` and the localizer on ``/localizer/regions``, both transient-local
so that an RViz started later still draws them.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from vbn_common.names import MAP_FRAME
from vbn_common.palette import region_colours

__all__ = ['LATCHED_QOS', 'region_markers']

#: Transient-local, reliable, depth 1: what RViz needs to get markers published earlier.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


def region_markers(database: Any, frame_id: str = MAP_FRAME, stamp: Any = None) -> Any:
    """Return the ``MarkerArray`` of a :class:`~landmark_db.database.LandmarkDatabase`."""
    from geometry_msgs.msg import Point
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker, MarkerArray


    xy = database.poses.xy
    spacing = database.poses.spacing or _nearest_spacing(xy)
    colours = region_colours(len(database.regions))
    out = MarkerArray()
    clear = Marker(action=Marker.DELETEALL)
    clear.header.frame_id = frame_id
    out.markers.append(clear)
    for index, region in enumerate(database.regions):
        marker = Marker(ns='regions', id=index, type=Marker.CUBE_LIST, action=Marker.ADD)
        marker.header.frame_id = frame_id
        if stamp is not None:
            marker.header.stamp = stamp
        marker.pose.orientation.w = 1.0
        side = 0.8 * spacing
        marker.scale.x, marker.scale.y, marker.scale.z = side, side, 0.01
        r, g, b, _a = (float(c) for c in colours[index])
        marker.color = ColorRGBA(r=r, g=g, b=b, a=0.6)
        z = 0.005 * index
        marker.points = [Point(x=float(x), y=float(y), z=z) for x, y in xy[region.poses]]
        out.markers.append(marker)
    views = Marker(ns='model_views', id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
    views.header.frame_id = frame_id
    views.pose.orientation.w = 1.0
    views.scale.x = views.scale.y = views.scale.z = 0.5 * spacing
    for index, region in enumerate(database.regions):
        r, g, b, _a = (float(c) for c in colours[index])
        for view in region.model_views:
            views.points.append(Point(x=view.x, y=view.y, z=0.3))
            views.colors.append(ColorRGBA(r=r, g=g, b=b, a=1.0))
    out.markers.append(views)
    return out


def _nearest_spacing(xy: np.ndarray) -> float:
    if len(xy) < 2:
        return 0.25
    from scipy.spatial import cKDTree
    distances, _ = cKDTree(xy).query(xy, k=2)
    return float(np.median(distances[:, 1])) or 0.25
