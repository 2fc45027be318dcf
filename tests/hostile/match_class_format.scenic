# class: dunder-format
# caught-by: safety
# str.format reached through a class pattern instead of an attribute, then walked into globals
param map = 'highway_straight'
model scenic.domains.driving.model

def helper():
    return 0

match "{0." + chr(95) * 2 + "globals" + chr(95) * 2 + "}":
    case str(format=walk):
        pass
leak = walk(helper)

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
