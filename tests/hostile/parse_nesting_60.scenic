# class: parser-resource
# caught-by: precheck
# brackets nested 60 deep: the parser recurses per level
param map = 'highway_straight'
model scenic.domains.driving.model
x = ((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((1))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
