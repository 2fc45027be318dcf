# class: env-object-graph
# caught-by: safety
# an assignment expression keeps the simulation while reading an allowed attribute
param map = 'highway_straight'
model scenic.domains.driving.model
behavior Pwn():
    if (s := simulation()).currentTime > 0:
        s.env
    wait

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
