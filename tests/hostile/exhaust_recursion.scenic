# class: resource-exhaustion
# caught-by: sandbox
# limit: recursion
# unbounded recursion
param map = 'highway_straight'
model scenic.domains.driving.model
def down(n):
    return down(n + 1)
depth = down(0)

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
