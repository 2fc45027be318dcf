# class: env-object-graph
# caught-by: safety
# the simulation function kept as a class attribute
param map = 'highway_straight'
model scenic.domains.driving.model
class Holder:
    get = simulation
Holder.get().env

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
