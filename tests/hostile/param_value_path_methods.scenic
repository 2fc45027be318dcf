# class: param-path
# caught-by: safety
# file-system methods of a path-typed value, reached from an object's attribute
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    where = self.position
    where.write_text("x")
    where.rename('/tmp/dv2s-hostile-marker')
    where.stat()
    where.replace('/tmp/dv2s-hostile-marker')
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
