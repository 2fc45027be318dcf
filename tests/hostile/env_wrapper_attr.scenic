# class: env-object-graph
# caught-by: safety
# Gymnasium's wrapper accessors reach any attribute by name
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    simulation().env.get_wrapper_attr("spec")
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
