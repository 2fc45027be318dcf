'''
To run this file using the Carla simulator:
    scenic examples/carla/pedestrian.scenic --2d --model scenic.simulators.carla.model --simulate
'''
param map = localPath('maps/Town04.xodr')
param carla_map = 'Town04'
model scenic.simulators.carla.model

ego = new Car
new Pedestrian on visible sidewalk