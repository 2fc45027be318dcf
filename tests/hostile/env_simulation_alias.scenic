# class: env-object-graph
# caught-by: safety
# the simulation bound to a name, then walked one attribute at a time
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    sim = simulation()
    env = sim.env
    env.unwrapped.close()
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
