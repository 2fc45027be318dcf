# class: imports
# caught-by: safety
# an allowed module, a name outside its allowlist (a sampler object reaches files and modules)
param map = 'highway_straight'
model scenic.domains.driving.model
from scenic.core.external_params import VerifaiRange, VerifaiSampler
gap = VerifaiRange(5, 10)
ego = new Car with speed 10
