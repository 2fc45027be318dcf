# class: param-path
# caught-by: safety
# building a path to another file from a path value
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    self.lane.joinpath("x").with_suffix(".py").resolve()
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
