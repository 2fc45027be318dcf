# class: file-process-network
# caught-by: safety
# a path object joined with an absolute path, then mkdir: no file-system method name in a string
param map = 'highway_straight'
model scenic.domains.driving.model
here = localPath("x")
(here / "/tmp/dv2s-hostile-marker").mkdir()

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
