# class: env-object-graph
# caught-by: safety
# a coroutine's frame reaches the globals of the model
param map = 'highway_straight'
model scenic.domains.driving.model
async def co():
    pass
frame = co().cr_frame

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
