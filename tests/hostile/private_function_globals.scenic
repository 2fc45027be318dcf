# class: private-attribute
# caught-by: safety
# the script's own function globals
param map = 'highway_straight'
model scenic.domains.driving.model
def helper():
    return 0
helper.__globals__["__builtins__"]["open"]("/tmp/dv2s-hostile-marker", "w").write("x")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
