# class: dunder-format
# caught-by: safety
# strings naming private attributes (for any lookup-by-name helper)
param map = 'highway_straight'
model scenic.domains.driving.model
name = "__globals__"
other = "_os"

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
