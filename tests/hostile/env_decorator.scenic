# class: env-object-graph
# caught-by: safety
# simulation used as a decorator, so the function name is bound to whatever it returns
param map = 'highway_straight'
model scenic.domains.driving.model
@simulation
def sim():
    pass

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
