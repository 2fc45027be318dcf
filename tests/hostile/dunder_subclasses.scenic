# class: dunder-format
# caught-by: safety
# object.__subclasses__ finds subprocess.Popen
param map = 'highway_straight'
model scenic.domains.driving.model
classes = ().__class__.__base__.__subclasses__()
popen = [c for c in classes if c.__name__ == "Popen"][0]
popen(["touch", "/tmp/dv2s-hostile-marker"])

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
