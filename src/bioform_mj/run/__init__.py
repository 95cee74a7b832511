"""One closed-loop run: build the plant and controller, drive the loop, inject faults, summarise (design §9)."""
