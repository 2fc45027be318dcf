# class: env-object-graph
# caught-by: safety
# the env's generator, to predict or reseed every later sample
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    rng = simulation().env.np_random
    rng.bit_generator.state = {"state": 0}
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
