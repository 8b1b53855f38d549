"""Settings for the whole suite.

Every DDS participant a test starts (in this process or a child) discovers only this machine:
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, so no discovery traffic leaves the host. Tests of the
other ranges set their own, inside network namespaces of their own.
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ.pop("ROS_LOCALHOST_ONLY", None)
