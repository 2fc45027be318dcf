# class: imports
# caught-by: safety
# the allowed VerifAI module imported whole, then walked to os
param map = 'highway_straight'
model scenic.domains.driving.model
import scenic.core.external_params as ep
ep.os.system("touch /tmp/dv2s-hostile-marker")
ego = new Car with speed 10
