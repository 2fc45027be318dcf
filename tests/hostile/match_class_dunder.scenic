# class: private-attribute
# caught-by: safety
# a class pattern reads dunder attributes (`case Cls(attr=x)` is getattr): object, a function's globals, builtins, os
param map = 'highway_straight'
model scenic.domains.driving.model

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None

match ego:
    case Car(__reduce_ex__=reduce):
        parts = reduce(0)
base = parts[1][1]
match parts[0]:
    case base(__globals__=namespace):
        found = namespace[chr(95) * 2 + "builtins" + chr(95) * 2]
match found:
    case dict():
        load = found[chr(95) * 2 + "import" + chr(95) * 2]
    case base(__import__=load):
        pass
load("os").mkdir("/tmp/dv2s-hostile-marker")
