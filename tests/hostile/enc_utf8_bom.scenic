# class: encoding
# caught-by: precheck
# a UTF-8 byte-order mark: utf-8-sig source
param map = 'highway_straight'
model scenic.domains.driving.model

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
