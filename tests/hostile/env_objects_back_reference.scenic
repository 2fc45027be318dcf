# class: env-object-graph
# caught-by: safety
# from the simulation's objects back to the simulation and its env
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    simulation().objects[0].simulation.env
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
