# coding: latin-1
# class: encoding
# caught-by: precheck
# a latin-1 coding declaration makes the bytes read differ from a UTF-8 check
param map = 'highway_straight'
model scenic.domains.driving.model
name = 'é'

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
