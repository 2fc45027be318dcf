# class: env-object-graph
# caught-by: safety
# highway-env's change_vehicles imports a module by name
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    simulation().env.unwrapped.change_vehicles("evil.Vehicle")
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
