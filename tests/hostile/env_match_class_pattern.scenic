# class: env-object-graph
# caught-by: safety
# a match statement reads the env through a class pattern's keyword
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    match simulation():
        case object(env=e):
            e.reset()
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
