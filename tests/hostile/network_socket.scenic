# class: file-process-network
# caught-by: safety
# network access
param map = 'highway_straight'
model scenic.domains.driving.model
import socket
socket.create_connection(("127.0.0.1", 9)).send(b"/tmp/dv2s-hostile-marker")

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
lead = new Car following roadDirection from ego for Range(15, 30),
    with behavior None
