"""tf2_msgs, built by the set-up from interfaces/ where ROS 2 is not installed, is the
distribution's: its type hash is ROS 2 Jazzy's (what `ros2 topic info -v /tf` shows for AMCL's
or robot_state_publisher's /tf), and a TFMessage goes out and comes back over DDS."""
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.executors import SingleThreadedExecutor

from tf2_msgs.msg import TFMessage

JAZZY_TF_MESSAGE_HASH = \
    "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"


def test_tf_message_is_jazzys_and_travels(ros_context):
    node = rclpy.create_node("tf_probe", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        got = []
        pub = node.create_publisher(TFMessage, "/tf", 10)
        node.create_subscription(TFMessage, "/tf", got.append, 10)
        info = node.get_publishers_info_by_topic("/tf")
        assert info[0].topic_type == "tf2_msgs/msg/TFMessage"
        assert str(info[0].topic_type_hash) == JAZZY_TF_MESSAGE_HASH
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = "odom", "base_link"
        t.transform.translation.x, t.transform.rotation.w = 1.25, 1.0
        deadline = time.monotonic() + 10.0
        while not got:
            assert time.monotonic() < deadline, "no TFMessage came back"
            pub.publish(TFMessage(transforms=[t]))
            executor.spin_once(timeout_sec=0.05)
        back = got[0].transforms[0]
        assert (back.header.frame_id, back.child_frame_id) == ("odom", "base_link")
        assert back.transform.translation.x == 1.25
    finally:
        executor.shutdown()
        node.destroy_node()
