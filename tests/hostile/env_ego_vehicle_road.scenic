# class: env-object-graph
# caught-by: safety
# from an object to its highway-env vehicle, road and the road's generator
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    self.vehicle.road.np_random
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
