# class: env-object-graph
# caught-by: safety
# rewrite the env's limits through its config (step_time_limit) from inside a behaviour
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    simulation().env.unwrapped.config["step_time_limit"] = 1e9
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
