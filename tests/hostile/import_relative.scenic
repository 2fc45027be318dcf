# class: imports
# caught-by: safety
# relative imports
param map = 'highway_straight'
model scenic.domains.driving.model
from . import evil
from ..envs import dv2s_env

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
