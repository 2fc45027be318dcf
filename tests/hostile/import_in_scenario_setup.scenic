# class: imports
# caught-by: safety
# import inside a modular scenario's setup block
param map = 'highway_straight'
model scenic.domains.driving.model
scenario Main():
    setup:
        import os
        os.system("touch /tmp/dv2s-hostile-marker")
        ego = new Car
