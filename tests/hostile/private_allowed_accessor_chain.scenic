# class: private-attribute
# caught-by: safety
# a documented optional accessor, then a dunder chain from what it returns
param map = 'highway_straight'
model scenic.domains.driving.model
section = network.lanes[0].sections[0]._laneToLeft
section.__class__.__init__.__globals__["os"].system("touch /tmp/dv2s-hostile-marker")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
