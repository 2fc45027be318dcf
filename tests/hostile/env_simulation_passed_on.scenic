# class: env-object-graph
# caught-by: safety
# the simulation passed to a helper function, so no attribute follows it at the call site
param map = 'highway_straight'
model scenic.domains.driving.model
def walk(s):
    return s.env
behavior Pwn():
    walk(simulation())
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
