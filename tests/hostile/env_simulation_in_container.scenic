# class: env-object-graph
# caught-by: safety
# the simulation put in a list and taken out again
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    holder = [simulation()]
    holder[0].env
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
