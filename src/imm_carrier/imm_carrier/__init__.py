"""IMM carrier-phase tracking with data-bit modes and h-coefficient clock models, beside a Costas PLL
baseline (Zhao, Khanafseh, Pervan).
"""
