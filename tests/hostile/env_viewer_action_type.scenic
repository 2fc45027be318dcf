# class: env-object-graph
# caught-by: safety
# the env's viewer and action/observation types hold pygame and the vehicle objects
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    simulation().env.viewer.close()
    simulation().env.action_type.controlled_vehicle.road.vehicles.clear()
    simulation().env.observation_type.env
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
