# class: dunder-format
# caught-by: safety
# an exception's traceback reaches frames
param map = 'highway_straight'
model scenic.domains.driving.model
try:
    1 / 0
except ZeroDivisionError as error:
    tb = error.with_traceback(None)
    frame = error.__traceback__.tb_frame
    frame.f_back.f_globals["__builtins__"]["open"]("/tmp/dv2s-hostile-marker", "w")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
