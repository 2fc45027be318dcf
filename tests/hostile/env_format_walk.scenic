# class: env-object-graph
# caught-by: safety
# a format string walks the simulation's attributes
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    text = "{0.env.spec.kwargs}".format(simulation())
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
