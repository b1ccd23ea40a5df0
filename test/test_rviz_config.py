"""config/ecahd.rviz shows what the nodes publish: every display's topic is one a node of this
package creates a publisher for, with the QoS it publishes with (transient_local where latched),
and the goal and initial-pose tools send where global_planner and sim_bridge listen. Read from
the sources, so a renamed topic fails here."""
import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
PUBLISH = re.compile(r'(?:create_(?:lifecycle_)?publisher|lifecycle)\(\s*[\w.]+,\s*"([^"]+)"')
# create_subscription(Type, "topic", ...) or a (Type, "topic", self._on_..., QOS) table row
SUBSCRIBE = re.compile(r'(?:create_subscription\(|\()\s*[\w.]+,\s*"([^"]+)",\s*'
                       r'(?:guard|self\._on_)')


def topics(pattern) -> set[str]:
    found = set()
    for path in [*ROOT.glob("ecahd_ros/*.py"), *ROOT.glob("sim_bridge/*.py")]:
        found |= {"/" + t.lstrip("/") for t in pattern.findall(path.read_text())}
    return found


def test_every_display_shows_a_published_topic_and_the_tools_reach_the_nodes():
    config = yaml.safe_load((ROOT / "config" / "ecahd.rviz").read_text())
    manager = config["Visualization Manager"]
    published, subscribed = topics(PUBLISH), topics(SUBSCRIBE)
    assert {"/plan", "/local_plan", "/map", "/scan"} <= published  # the reading works
    shown = []
    for display in manager["Displays"]:
        topic = display.get("Topic", {}).get("Value")
        if topic is None:
            continue
        assert topic in published, (display["Name"], topic)
        shown.append(topic)
        latched = topic in ("/map", "/plan")  # MAP_QOS, PLAN_QOS: transient_local
        assert (display["Topic"].get("Durability Policy") == "Transient Local") == latched
    for wanted in ("/map", "/plan", "/local_plan", "/local_plan_footprints", "/plan_candidates",
                   "/scan", "/local_costmap"):
        assert wanted in shown, wanted
    assert any(d["Class"] == "rviz_default_plugins/TF" for d in manager["Displays"])
    tools = {t["Class"]: t.get("Topic", {}).get("Value") for t in manager["Tools"]}
    assert tools["rviz_default_plugins/SetGoal"] in subscribed  # global_planner's goal_pose
    assert tools["rviz_default_plugins/SetInitialPose"] in subscribed  # sim_bridge's teleport
    assert manager["Global Options"]["Fixed Frame"] == "map"
