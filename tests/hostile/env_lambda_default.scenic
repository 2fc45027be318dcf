# class: env-object-graph
# caught-by: safety
# the simulation function captured as a lambda's default argument
param map = 'highway_straight'
model scenic.domains.driving.model
grab = lambda sim=simulation: sim().env

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
