# class: env-object-graph
# caught-by: safety
# Gymnasium's EnvSpec imports and calls any entry point: the simulation leads to the env, the env to its spec
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    spec = simulation().env.spec
    spec.entry_point = "os:system"
    spec.make()
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
