# class: builtins
# caught-by: safety
# getattr with string constants
param map = 'highway_straight'
model scenic.domains.driving.model
opener = getattr(getattr(Car, "__init__"), "__globals__")["__builtins__"]["open"]
opener("/tmp/dv2s-hostile-marker", "w")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
