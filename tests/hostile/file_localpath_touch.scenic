# class: file-process-network
# caught-by: safety
# localPath returns a pathlib.Path: touch creates any file (mkdir, unlink, rename... work the same way)
param map = 'highway_straight'
model scenic.domains.driving.model
target = localPath("/tmp/dv2s-hostile-marker")
target.touch()

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
