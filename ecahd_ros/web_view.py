"""web_view: a live view of the robot in a web browser, for a pip-only install (no RViz, no
Foxglove app, no network): the map, the local costmap's obstacles, the global plan and its goal
(with its heading), the local plan being followed and the robot's footprint, redrawn five times a
second. ``ros2 run ecahd_ros web_view`` beside the nodes (or ``ecahd demo --view``), then open
http://localhost:8080 (``port``); the page is one file of HTML and JavaScript served by the node,
nothing is fetched from elsewhere.

Parameters: ``port`` (8080), ``host`` ("127.0.0.1"; "0.0.0.0" serves other computers too),
``global_frame``, ``transform_tolerance``, ``robot`` / ``footprint`` / ``footprint_padding`` (the
outline drawn). A port already in use fails at start-up with one line.

Subscribes: map, plan, local_plan, local_costmap, odom (placed in ``global_frame`` through /tf,
as the planners do), /tf, /tf_static. Serves: ``/`` (the page), ``/map.png`` (the map, the top
row its far edge in y), ``/state.json`` (what the page draws; :func:`view_state`).
"""
from __future__ import annotations

import json
import threading
import time
from types import SimpleNamespace
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from rclpy.node import Node

from ecahd_core.errors import EcahdError
from ecahd_ros.callbacks import check_frame, guard
from ecahd_ros.conversions import heading_of, msg_to_grid, path_to_xy
from ecahd_ros.params import ParamSpec, declare_parameters, make_robot, shared
from ecahd_ros.qos import MAP_QOS, PLAN_QOS, STREAM_QOS, VIZ_QOS
from ecahd_ros.spin import spin_node
from ecahd_ros.tf_listener import TfListener, placed_odometry

PARAMETERS = [
    ParamSpec("port", 8080, "TCP port of the page"),
    ParamSpec("host", "127.0.0.1", "address the page is served on ('0.0.0.0': every "
                                   "interface, for another computer's browser)"),
    *shared("global_frame", "transform_tolerance", "robot", "footprint", "footprint_padding"),
]
MAX_POINTS = 2000  # a plan drawn with more points is thinned to this many


def _thin(xy: np.ndarray | None) -> list:
    if xy is None or len(xy) == 0:
        return []
    step = max(1, int(np.ceil(len(xy) / MAX_POINTS)))
    keep = xy[::step]
    if (len(xy) - 1) % step:  # the last point (the goal) always drawn
        keep = np.concatenate([keep, xy[-1:]])
    return np.round(keep, 3).tolist()


def view_state(*, grid=None, map_version: int = 0, pose=None, footprint=None, plan=None,
               goal_yaw=None, local_plan=None, obstacles=None, now: float = 0.0) -> dict:
    """What the page draws, JSON-ready: map bounds and version, the robot's pose [x, y, yaw]
    and footprint outline in the map frame, the plans (P, 2) [m], the goal with its heading
    (None: any) and the costmap's obstacle cells' centres (K, 2) [m]."""
    out = {"stamp": now, "map": None, "robot": None, "footprint": [], "plan": _thin(plan),
           "local_plan": _thin(local_plan), "goal": None, "obstacles": _thin(obstacles)}
    if grid is not None:
        x0, y0, x1, y1 = grid.bounds
        out["map"] = {"x0": x0, "y0": y0, "x1": x1, "y1": y1, "version": map_version,
                      "name": grid.name, "resolution": grid.resolution}
    if pose is not None:
        x, y, yaw = (float(v) for v in pose)
        out["robot"] = [round(x, 3), round(y, 3), round(yaw, 4)]
        if footprint is not None:
            c, s = np.cos(yaw), np.sin(yaw)
            outline = footprint.polygon @ np.array([[c, s], [-s, c]]) + [x, y]
            out["footprint"] = np.round(outline, 3).tolist()
    if plan is not None and len(plan):
        out["goal"] = {"xy": np.round(plan[-1], 3).tolist(),
                       "yaw": None if goal_yaw is None else round(float(goal_yaw), 4)}
    return out


def map_png(grid) -> bytes:
    """The map as a PNG: free white, occupied black, unknown grey; row 0 the top (far y)."""
    import cv2

    image = np.full(grid.occupied.shape, 255, dtype=np.uint8)
    image[grid.occupied] = 0
    image[grid.data < 0] = 160
    ok, data = cv2.imencode(".png", image[::-1])
    if not ok:
        raise EcahdError("cannot encode the map as PNG")
    return data.tobytes()


class WebView(Node):
    """The node: messages in, :func:`view_state` out over HTTP (a server thread)."""

    def __init__(self, **kwargs) -> None:
        super().__init__("web_view", **kwargs)
        declare_parameters(self, PARAMETERS)
        get = lambda name: self.get_parameter(name).value  # noqa: E731
        self.frame, self.tolerance = get("global_frame"), float(get("transform_tolerance"))
        self.footprint = make_robot(SimpleNamespace(
            robot=get("robot"), footprint=get("footprint"),
            footprint_padding=float(get("footprint_padding"))))
        self._lock = threading.Lock()
        self._grid, self._png, self._version = None, b"", 0
        self._pose = self._plan = self._goal_yaw = self._local = self._obstacles = None
        self.tf = TfListener(self)
        for msg_type, topic, callback, qos in (
                (OccupancyGrid, "map", self._on_map, MAP_QOS),
                (Path, "plan", self._on_plan, PLAN_QOS),
                (Path, "local_plan", self._on_local_plan, VIZ_QOS),
                (OccupancyGrid, "local_costmap", self._on_costmap, VIZ_QOS),
                (Odometry, "odom", self._on_odom, STREAM_QOS)):
            self.create_subscription(msg_type, topic, guard(self, callback), qos)
        try:
            self.server = ThreadingHTTPServer((get("host"), int(get("port"))), self._handler())
        except OSError as exc:
            raise EcahdError(f"cannot serve the view on {get('host')}:{get('port')}: "
                             f"{exc.strerror} (set the port parameter)") from None
        self.server.daemon_threads = True
        threading.Thread(target=self.server.serve_forever, name="web_view",
                         daemon=True).start()
        host, port = self.server.server_address[:2]
        self.get_logger().info(f"live view on http://{'localhost' if host == '127.0.0.1' else host}:"
                               f"{port}")

    @property
    def port(self) -> int:
        return self.server.server_address[1]

    def destroy_node(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        super().destroy_node()

    # ------------------------------------------------------------------------ callbacks
    def _on_map(self, msg: OccupancyGrid) -> None:
        check_frame(msg.header.frame_id, self.frame, "map")
        grid = msg_to_grid(msg, name="map")
        png = map_png(grid)
        with self._lock:
            self._grid, self._png, self._version = grid, png, self._version + 1

    def _on_plan(self, msg: Path) -> None:
        check_frame(msg.header.frame_id, self.frame, "plan")
        xy = path_to_xy(msg)
        yaw = heading_of(msg.poses[-1].pose.orientation) if msg.poses else None
        with self._lock:
            self._plan, self._goal_yaw = (xy if len(xy) else None), yaw

    def _on_local_plan(self, msg: Path) -> None:
        check_frame(msg.header.frame_id, self.frame, "local_plan")
        with self._lock:
            self._local = path_to_xy(msg)

    def _on_costmap(self, msg: OccupancyGrid) -> None:
        check_frame(msg.header.frame_id, self.frame, "local_costmap")
        window = msg_to_grid(msg, name="local_costmap", unknown_is_occupied=False)
        rows, cols = np.nonzero(window.occupied)
        ox, oy = window.origin
        centres = np.stack([ox + (cols + 0.5) * window.resolution,
                            oy + (rows + 0.5) * window.resolution], axis=1)
        with self._lock:
            self._obstacles = centres

    def _on_odom(self, msg: Odometry) -> None:
        pose = placed_odometry(self, msg, self.tf.buffer, self.frame, self.tolerance)
        if pose is not None:
            with self._lock:
                self._pose = pose

    # ------------------------------------------------------------------------- the page
    def state(self) -> dict:
        with self._lock:
            return view_state(grid=self._grid, map_version=self._version, pose=self._pose,
                              footprint=self.footprint, plan=self._plan,
                              goal_yaw=self._goal_yaw, local_plan=self._local,
                              obstacles=self._obstacles, now=time.time())

    def _handler(self):
        view = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 (http.server's name)
                path = self.path.split("?")[0]
                if path == "/":
                    body, kind = PAGE.encode(), "text/html; charset=utf-8"
                elif path == "/state.json":
                    body, kind = json.dumps(view.state()).encode(), "application/json"
                elif path == "/map.png":
                    with view._lock:
                        body = view._png
                    kind = "image/png"
                    if not body:
                        self.send_error(404, "no map yet")
                        return
                else:
                    self.send_error(404)
                    return
                self.send_response(200)
                self.send_header("Content-Type", kind)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args) -> None:  # quiet: five requests a second
                pass

        return Handler


PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>ecahd_ros live view</title>
<style>
 body { margin: 0; font: 14px sans-serif; background: #222; color: #eee; }
 #bar { padding: 6px 10px; } #bar span { margin-right: 18px; }
 canvas { display: block; margin: 0 auto; background: #444; }
 .k { display: inline-block; width: 12px; height: 4px; margin-right: 4px; vertical-align: middle; }
</style></head>
<body>
<div id="bar"><b>ecahd_ros</b> <span id="status">waiting for the map...</span>
 <span><i class="k" style="background:#8e44ad"></i>global plan</span>
 <span><i class="k" style="background:#2e86de"></i>local plan</span>
 <span><i class="k" style="background:#e74c3c"></i>scanned obstacles</span>
 <span><i class="k" style="background:#27ae60"></i>robot</span></div>
<canvas id="view"></canvas>
<script>
const canvas = document.getElementById("view"), ctx = canvas.getContext("2d");
const status = document.getElementById("status");
let mapImage = null, mapVersion = -1, state = null;
function fit(m) {
  const w = window.innerWidth - 20, h = window.innerHeight - 50;
  const s = Math.min(w / (m.x1 - m.x0), h / (m.y1 - m.y0));
  canvas.width = Math.round((m.x1 - m.x0) * s); canvas.height = Math.round((m.y1 - m.y0) * s);
  return s;
}
function px(m, s, p) { return [(p[0] - m.x0) * s, (m.y1 - p[1]) * s]; }
function line(m, s, pts, color, width, dots) {
  if (!pts.length) return;
  ctx.strokeStyle = color; ctx.fillStyle = color; ctx.lineWidth = width; ctx.beginPath();
  pts.forEach((p, i) => { const q = px(m, s, p); i ? ctx.lineTo(q[0], q[1]) : ctx.moveTo(q[0], q[1]); });
  ctx.stroke();
  if (dots) pts.forEach(p => { const q = px(m, s, p); ctx.beginPath(); ctx.arc(q[0], q[1], 3, 0, 7); ctx.fill(); });
}
function arrow(m, s, xy, yaw, len, color) {
  const a = px(m, s, xy), b = px(m, s, [xy[0] + len * Math.cos(yaw), xy[1] + len * Math.sin(yaw)]);
  ctx.strokeStyle = color; ctx.lineWidth = 3; ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
}
function draw() {
  if (!state || !state.map) return;
  const m = state.map, s = fit(m);
  if (mapImage && mapImage.complete) { ctx.imageSmoothingEnabled = false; ctx.drawImage(mapImage, 0, 0, canvas.width, canvas.height); }
  const cell = Math.max(2, m.resolution * s);
  ctx.fillStyle = "#e74c3c";
  state.obstacles.forEach(p => { const q = px(m, s, p); ctx.fillRect(q[0] - cell / 2, q[1] - cell / 2, cell, cell); });
  line(m, s, state.plan, "#8e44ad", 3, true);
  line(m, s, state.local_plan, "#2e86de", 2, false);
  if (state.goal) {
    const g = px(m, s, state.goal.xy);
    ctx.fillStyle = "#f1c40f"; ctx.beginPath(); ctx.arc(g[0], g[1], 7, 0, 7); ctx.fill();
    if (state.goal.yaw !== null) arrow(m, s, state.goal.xy, state.goal.yaw, 0.6, "#f1c40f");
  }
  if (state.footprint.length) {
    ctx.fillStyle = "rgba(39,174,96,0.6)"; ctx.strokeStyle = "#1e8449"; ctx.lineWidth = 2; ctx.beginPath();
    state.footprint.forEach((p, i) => { const q = px(m, s, p); i ? ctx.lineTo(q[0], q[1]) : ctx.moveTo(q[0], q[1]); });
    ctx.closePath(); ctx.fill(); ctx.stroke();
  }
  if (state.robot) arrow(m, s, state.robot, state.robot[2], 0.5, "#145a32");
  const r = state.robot;
  status.textContent = "map " + (m.x1 - m.x0).toFixed(1) + " x " + (m.y1 - m.y0).toFixed(1) + " m" + (r ? "  robot (" + r[0].toFixed(2) + ", " + r[1].toFixed(2) +
      ", " + (r[2] * 180 / Math.PI).toFixed(0) + " deg)" : "  no robot pose yet") +
      (state.goal ? "  goal (" + state.goal.xy[0].toFixed(2) + ", " + state.goal.xy[1].toFixed(2) + ")" : "");
}
async function poll() {
  try {
    const r = await fetch("/state.json", {cache: "no-store"});
    state = await r.json();
    if (state.map && state.map.version !== mapVersion) {
      mapVersion = state.map.version; mapImage = new Image();
      mapImage.onload = draw; mapImage.src = "/map.png?v=" + mapVersion;
    }
    draw();
  } catch (e) { status.textContent = "the node does not answer: " + e; }
  setTimeout(poll, 200);
}
window.onresize = draw;
poll();
</script></body></html>
"""


def main(args=None) -> None:
    spin_node(WebView, args, name="web_view")


if __name__ == "__main__":
    main()
