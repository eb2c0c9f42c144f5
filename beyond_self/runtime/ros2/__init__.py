"""ROS 2 without ROS installed: rmw_zenoh's keys and attachments, CDR conversion through
rosbags, rosbag2 bags as recordings."""
