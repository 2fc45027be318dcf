# class: builtins
# caught-by: safety
# Scenic's model() imports any module by name
param map = 'highway_straight'
model scenic.domains.driving.model
namespace = {}
model(namespace, "os")
namespace["system"]("touch /tmp/dv2s-hostile-marker")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
