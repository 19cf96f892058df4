:- consult('../../tartarus.pl').
:- consult(tour).
node_label(bravo).
:- start_tartarus(localhost, 7002, 1111).
