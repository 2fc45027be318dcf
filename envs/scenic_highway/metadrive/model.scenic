"""Scenic's MetaDrive world model (scenic.simulators.metadrive.model, Scenic 3.1.1) on highway-env.

A script whose ``model`` line names ``scenic.simulators.metadrive.model`` is compiled
against this file, which extends ``envs/scenic_highway/model.scenic``: MetaDrive's
classes (``Car``, ``Pedestrian``; the other driving classes are ours), the driving
domain's actions and behaviours, and MetaDrive's global parameters. ``sumo_map``
(MetaDrive reads the road network from a SUMO file next to the OpenDRIVE map) is
accepted and not required: highway-env reads the OpenDRIVE map itself.
``render``, ``render3D``, ``real_time`` and the screen-recording parameters only
concern MetaDrive's window and are ignored. ``metaDriveActor`` fails with an
``UnsupportedConstructError``.
"""

from envs.scenic_highway.model import *
from scenic.domains.driving.actions import *
from scenic.domains.driving.behaviors import *
from envs.scenic_highway.model_support import NoMetaDriveActor as _NoMetaDriveActor

simulator HighwayEnvSimulator(network)

import pathlib as _pathlib
param sumo_map = str(_pathlib.Path(globalParameters.map).with_suffix(".net.xml"))
param render = 1
param render3D = 0
param real_time = 1
param screen_record = 0

class Car(Car, _NoMetaDriveActor):
    """A car."""
    pass

class Pedestrian(Pedestrian, _NoMetaDriveActor):
    """A pedestrian."""
    pass
