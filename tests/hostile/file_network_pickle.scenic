# class: file-process-network
# caught-by: safety
# a public Scenic method that writes a pickle file
param map = 'highway_straight'
model scenic.domains.driving.model
network.dumpPickle("/tmp/dv2s-hostile-marker", b"", b"")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
