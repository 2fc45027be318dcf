# class: env-object-graph
# caught-by: safety
# writing the simulation's clock to stop every monitor and time limit
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    simulation().currentTime = -1000000
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
