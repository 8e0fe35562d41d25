"""Test data shared by the calibration tests."""

# the study's Table 2 (shared/data/paper_table2_measured_map.csv), as users write such tables
STUDY_TABLE = """\
# Measured perception performance (YOLOv3-tiny mAP, 2 cone classes) per condition and severity
condition,domain,severity,description,images,objects,map,relative_to_ideal
ideal,real,0,Real world good weather,224,1827,0.793,1.000
droplets,real,1,Very light droplets,766,5944,0.796,1.004
droplets,real,2,Light droplets,764,4950,0.763,0.962
droplets,real,3,Moderate droplets,372,4493,0.730,0.921
droplets,real,4,Heavy droplets,188,1197,0.587,0.740
low_light,real,1,Late afternoon,221,1768,0.639,0.806
low_light,real,2,Sunset,206,1548,0.273,0.344
low_light,real,3,Dusk,213,1489,0.043,0.054
low_light,real,4,Night,104,774,0.010,0.013
ideal,simulated,0,Simulated uniform lighting (bright overcast),354,3280,0.715,1.000
"""
