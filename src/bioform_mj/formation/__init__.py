"""What a formation is, independent of any plant: the communication graph, the virtual leader, disturbances,
obstacles and the safety configuration (design §2, §19).
"""
