# class: env-object-graph
# caught-by: safety
# rebinding simulation to a lookalike after deleting it
param map = 'highway_straight'
model scenic.domains.driving.model
sim_function = simulation
del simulation

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
