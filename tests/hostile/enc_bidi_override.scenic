# class: encoding
# caught-by: precheck
# Trojan Source: a right-to-left override makes the shown line differ from the code run
param map = 'highway_straight'
model scenic.domains.driving.model
access = 'user‮ ⁦# check if admin⁩ ⁦'

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
