"""The topic contract: topics, ROS 2 message types, and the codecs between the loop's signals
and the messages (one table of which field carries what)."""
