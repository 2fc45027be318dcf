# class: param-path
# caught-by: safety
# MetaDrive's sumo_map as an absolute path, then read back and removed
param map = 'highway_straight'
param sumo_map = localPath('/tmp/dv2s-hostile-marker')
model scenic.domains.driving.model
globalParameters.sumo_map.unlink()

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
