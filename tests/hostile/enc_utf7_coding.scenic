# -*- coding: utf-7 -*-
# class: encoding
# caught-by: precheck
# a utf-7 coding declaration: +AAo- is a newline for Python, so the import is code, not a comment
param map = 'highway_straight'
model scenic.domains.driving.model
# harmless +AAo-import os+AAo-os.system('touch /tmp/dv2s-hostile-marker')

lane = Uniform(*network.lanes)
ego = new Car at lane.centerline.pointAlongBy(Range(100, 500)), with speed 20
