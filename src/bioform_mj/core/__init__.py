"""The floor every other package stands on: errors, the paper's equations written once with their JIT set-up, the
loop's compiled types, budgets, dependency checks and the one code hash (design §9, §16, §17).
"""
