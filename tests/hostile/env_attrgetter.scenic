# class: env-object-graph
# caught-by: safety
# operator.attrgetter walks attributes without getattr
param map = 'highway_straight'
model scenic.domains.driving.model
import operator
walk = operator.attrgetter("env.spec")
walk(simulation())

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
