# class: env-object-graph
# caught-by: safety
# from the lane-following controllers to the simulator
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    lon, lat = simulation().getLaneFollowingControllers(self)
    lon.simulator.env
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
