# class: file-process-network
# caught-by: safety
# choosing or constructing a simulator
param map = 'highway_straight'
model scenic.domains.driving.model
simulator HighwayEnvSimulator()

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
