# class: env-object-graph
# caught-by: safety
# from the simulation to Scenic's simulator object, which creates simulations
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    simulation().simulator.createSimulation(None)
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
