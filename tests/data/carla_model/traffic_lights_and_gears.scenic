param map = localPath('Town01.xodr')
param carla_map = 'Town01'
model scenic.simulators.carla.model

behavior CautiousDriver():
    take SetGearAction(1), SetVehicleLightStateAction(None)
    while True:
        if withinDistanceToRedYellowTrafficLight(self, 15):
            take SetBrakeAction(1)
        else:
            take SetThrottleAction(0.3)
        if getClosestTrafficLightStatus(self) is not None:
            terminate

ego = new Car
npc = new Car following roadDirection from ego for 15, with behavior CautiousDriver()
