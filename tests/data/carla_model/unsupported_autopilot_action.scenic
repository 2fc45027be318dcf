param map = localPath('Town01.xodr')
param carla_map = 'Town01'
model scenic.simulators.carla.model

behavior Hand():
    take SetAutopilotAction(True)

ego = new Car
npc = new Car following roadDirection from ego for 15, with behavior Hand()
