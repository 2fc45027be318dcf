# class: file-process-network
# caught-by: safety
# loading a (pickled) network from any path
param map = 'highway_straight'
model scenic.domains.driving.model
evil = Network.fromFile("/tmp/dv2s-hostile-marker.snet")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
