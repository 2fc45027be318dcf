# class: env-object-graph
# caught-by: safety
# an f-string formats the simulation object, whose repr names the env
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    text = f"{simulation()!r}"
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
