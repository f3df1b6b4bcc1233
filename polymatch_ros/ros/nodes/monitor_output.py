"""What the monitor publishes besides the headline diameters: diagnostics, the certificate and
RViz markers."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from rclpy.node import Node

    from ...core.certificate import CertificateKeeper
    from ...core.metrics import EnsembleMetrics
    from ...core.model import Group, Model
    from ...core.scenes.scene import Scene
    from ...core.so import RotationGroup
    from ..config.configs import MonitorConfig
    from ..wire.intake import DropCounter

GROUP_COLOURS = [
    (0.12, 0.47, 0.71),
    (0.84, 0.15, 0.16),
    (0.17, 0.63, 0.17),
    (0.58, 0.40, 0.74),
    (1.0, 0.50, 0.05),
    (0.09, 0.75, 0.81),
]


class MonitorView(Protocol):
    """What these outputs read of the monitor (``monitor.MonitorNode``)."""

    node: Node
    config: MonitorConfig
    scene: Scene
    model: Model
    grp: RotationGroup
    n: int
    drops: DropCounter


def diagnostics(
    mon: MonitorView, t: float, met: EnsembleMetrics, keep: Sequence[int], heard: int
) -> Any:
    """DiagnosticArray: the ensemble's status (diameter against the scene's tolerance, agents
    heard, drops) and one status per group with its metrics (Prop 2.1/2.2 quantities)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    arr = DiagnosticArray()
    arr.header.stamp = mon.node.get_clock().now().to_msg()
    name = mon.node.get_fully_qualified_name()
    top = DiagnosticStatus(name=f"polymatch{name}", hardware_id=name)
    tol = mon.scene.tolerance
    ok = met.diameter < tol
    top.level = DiagnosticStatus.OK if ok else DiagnosticStatus.WARN
    top.message = (
        f"t = {t:.6g}: matching diameter {met.diameter:.3e} "
        f"({'below' if ok else 'above'} tolerance {tol:g}); "
        f"{heard}/{mon.n} agents heard; {mon.drops.summary()}"
    )
    values: dict[str, Any] = {
        "t": t,
        "diameter": met.diameter,
        "agents_heard": heard,
        "agents": mon.n,
        "dropped": mon.drops.total,
    }
    if met.group_separation is not None:
        values["group_separation"] = met.group_separation
    top.values = [
        KeyValue(key=k, value=repr(float(v)) if isinstance(v, float) else str(v))
        for k, v in values.items()
    ]
    statuses = [top]
    ns = mon.node.get_namespace().strip("/")
    for gi, gm in zip(keep, met.groups):
        g = mon.model.groups[gi]
        st = DiagnosticStatus(
            name=f"polymatch/{ns}/group/{g.name}",
            hardware_id=g.name,
            level=DiagnosticStatus.OK,
            message=f"matching diameter {gm.matching_diameter:.3e}",
        )
        st.values = [KeyValue(key=k, value=repr(float(v))) for k, v in asdict(gm).items()]
        statuses.append(st)
    arr.status = statuses
    return arr


def certificate_status(mon: MonitorView, keeper: CertificateKeeper) -> Any:
    """DiagnosticStatus of the run's certificate (``core.certificate``; the format is in
    docs/guide/ros-interface.md): level OK = granted, WARN = not (yet) certified, ERROR = granted
    and then breached by an observed diameter (the run left the model's flow); message = the
    one-line wording; values = the certificate's fields."""
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    cert = keeper.current
    assert cert is not None, "a certificate is published once evaluated"
    name = mon.node.get_fully_qualified_name()
    st = DiagnosticStatus(name=f"polymatch{name}/certificate", hardware_id=name)
    st.level = DiagnosticStatus.OK if cert.certified else DiagnosticStatus.WARN
    st.message = cert.line()
    values: dict[str, str] = {
        "certified": "true" if cert.certified else "false",
        "guaranteed_time": "" if cert.time is None else repr(cert.time),
        "tolerance": repr(cert.tolerance),
        "issued_at": repr(cert.t0),
        "theorem": cert.theorem,
        "reason": cert.reason,
        "centroid_rate": "" if cert.centroid_rate is None else repr(cert.centroid_rate),
    }
    if keeper.breach is not None:
        t, seen, bound = keeper.breach
        st.level = DiagnosticStatus.ERROR
        st.message += (f"; BREACHED at t = {t:.6g}: observed diameter {seen:.3e} > bound "
                       f"{bound:.3e} (the run is not the model's flow)")
        values.update(breach_t=repr(t), breach_observed=repr(seen), breach_bound=repr(bound))
    st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
    return st


def _marker(mon: MonitorView, g: Group, a: int, colour: tuple[float, float, float],
            verts: np.ndarray, stamp: Any) -> Any:
    from builtin_interfaces.msg import Duration
    from geometry_msgs.msg import Point
    from visualization_msgs.msg import Marker

    life = mon.config.peer_timeout
    m = Marker(type=Marker.LINE_LIST, action=Marker.ADD, ns=g.name, id=a)
    m.header.frame_id = mon.config.frame_id
    m.header.stamp = stamp
    m.scale.x = 0.03
    m.color.r, m.color.g, m.color.b = colour
    m.color.a = 1.0
    m.pose.orientation.w = 1.0
    m.lifetime = Duration(sec=int(life), nanosec=int((life % 1) * 1e9))
    for ea, eb in g.edges:
        for v in (verts[ea], verts[eb]):
            pt = np.zeros(3)
            pt[: min(3, len(v))] = v[:3]
            m.points.append(Point(x=float(pt[0]), y=float(pt[1]), z=float(pt[2])))
    return m


def markers(mon: MonitorView, poses: Mapping[int, tuple[Any, Any]]) -> Any:
    """MarkerArray: each heard polytope's edges, a colour per group; poses {agent: (x, rot)}."""
    from visualization_msgs.msg import MarkerArray

    arr = MarkerArray()
    stamp = mon.node.get_clock().now().to_msg()
    for gi, g in enumerate(mon.model.groups):
        colour = GROUP_COLOURS[gi % len(GROUP_COLOURS)]
        for a in g.indices:
            if a not in poses:
                continue
            x, rot = poses[a]
            s = 1.0 if g.scales is None else g.scales[a - g.start]
            verts = x + mon.scene.origin + s * g.reference @ mon.grp.to_matrices(rot)[0].T
            arr.markers.append(_marker(mon, g, a, colour, verts, stamp))
    return arr
