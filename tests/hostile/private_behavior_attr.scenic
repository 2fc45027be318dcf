# class: private-attribute
# caught-by: safety
# private attributes inside a behaviour
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Sneaky():
    take SetThrottleAction(0.5)
    self._simulator.__class__.__module__
    FollowLaneBehavior.__init__.__globals__["os"].system("touch /tmp/dv2s-hostile-marker")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior Sneaky()
