# class: file-process-network
# caught-by: safety
# a map path climbing out of the map folder
param map = 'highway_straight'
model scenic.domains.driving.model
param map = localPath("../../../../tmp/dv2s-hostile-marker.xodr")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
