"""Frames over time, as ROS's tf2 keeps them: rigid transforms (rigid.py) and the tree of
frames that ``/tf`` and ``/tf_static`` describe (buffer.py). No ROS: the nodes' tf listener
and broadcaster (nodes/tf.py), the importers and the replay share it."""
