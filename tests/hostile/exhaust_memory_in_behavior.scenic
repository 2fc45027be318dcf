# class: resource-exhaustion
# caught-by: sandbox
# limit: memory
# memory growing inside a behaviour
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Hog():
    take SetThrottleAction(0.1)
    blob = []
    while True:
        blob.append("y" * (10 ** 7))

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior Hog()
