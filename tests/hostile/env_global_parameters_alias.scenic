# class: env-object-graph
# caught-by: safety
# globalParameters bound to a name, then iterated for path objects
param map = 'highway_straight'
model scenic.domains.driving.model
params = globalParameters
for value in params.values():
    value.unlink()

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
