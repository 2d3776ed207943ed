#!/usr/bin/env python3
"""The CRV 2016 "Auction" traces (CSV, as PRECISE/SMEDL's tests/monitors/auction/ holds them:
`create_auction,item,reserve,days` / `bid,item,amount,` / `sold,item,,` / `endOfDay`) in the two
formats the Auction benchmark reads: TeSSLa's trace format for bench/auction.tessla (event n at
time n) and RTLola's CSV for bench/auction.lola (column `time` = n, one column per input, `#` =
no event, as rtlola-cli reads it).

Usage: python3 bench/auction_trace.py CSV OUT.input OUT.csv
"""
import sys


def main():
    src, tessla_out, csv_out = sys.argv[1:4]
    with open(src) as f, open(tessla_out, "w") as t, open(csv_out, "w") as c:
        c.write("time,create_item,create_reserve,create_days,bid_item,bid_amount,sold_item,end_of_day\n")
        for n, line in enumerate(f, 1):
            p = line.strip().split(",")
            if p[0] == "create_auction":
                t.write(f'{n}: create_auction = ("{p[1]}", {int(p[2])}, {int(p[3])})\n')
                c.write(f"{n},{p[1]},{int(p[2])},{int(p[3])},#,#,#,#\n")
            elif p[0] == "bid":
                t.write(f'{n}: bid = ("{p[1]}", {int(p[2])})\n')
                c.write(f"{n},#,#,#,{p[1]},{int(p[2])},#,#\n")
            elif p[0] == "sold":
                t.write(f'{n}: sold = "{p[1]}"\n')
                c.write(f"{n},#,#,#,#,#,{p[1]},#\n")
            elif p[0] == "endOfDay":
                t.write(f"{n}: endOfDay\n")
                c.write(f"{n},#,#,#,#,#,#,true\n")
            elif p[0]:
                sys.exit(f"{src}:{n}: unknown event {p[0]!r}")


if __name__ == "__main__":
    main()
