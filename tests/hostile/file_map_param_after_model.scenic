# class: file-process-network
# caught-by: safety
# a localPath map set after the model line stays a pathlib.Path in globalParameters (its replace moves files)
param map = 'highway_straight'
model scenic.domains.driving.model
param map = localPath("road.xodr")
globalParameters.map.touch()
moved = globalParameters.map.replace("/tmp/dv2s-hostile-marker")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
