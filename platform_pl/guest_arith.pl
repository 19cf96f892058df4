:- module(guest_arith,
          [ guest_eval/2,               % -Value, +Expression
            cheap/3,                    % +Expression, +Room0, -Room
            int_operands/2              % +Culprit, +Numbers
          ]).
:- use_module(guest_sizes, [bits_limit/1, over_bits/3, bits/2]).

/** <module> Arithmetic evaluated node by node, each node's size checked

guest_eval/2 is is/2 for guest code (guest_limits.pl): it evaluates an
expression bottom up and checks the operands of each node that costs
more than linear time, or makes more bits than its operands have,
against dfrl_guest_integer_bits before GMP is called.
*/

:- set_prolog_flag(optimise, true).     % this file: arithmetic compiled inline

%!  guest_eval(-Value, +Expression) is det.
%
%   As is/2, evaluated node by node; a node that would make or work on an
%   integer over dfrl_guest_integer_bits raises before GMP is called.

guest_eval(V, E) :-
    (   number(E)
    ->  V = E
    ;   cheap(E, 1024, _)                    % at most 65,536 bits
    ->  system:is(V, E)
    ;   compound(E),
        \+ E = [_|_],
        compound_name_arity(E, F, A),
        A > 0
    ->  compound_name_arity(E1, F, A),
        eval_args(F, 1, A, E, E1, Vs),
        check_op(F, Vs, E1),
        system:is(V, E1)
    ;   system:is(V, E)
    ).

%   cheap(+Expr, +Room0, -Room): Expr has no power or shift, its
%   integers fit in 60 bits and it has fewer than Room0 leaves: no value
%   of it has more than 64 bits a leaf (a product of n such numbers has
%   at most 64n bits: 65,536 bits, under any sensible
%   dfrl_guest_integer_bits; a smaller limit is checked node by node for
%   expressions of more than a few leaves only). The common case (N + 1,
%   X * 2.0 + Y), evaluated at once.
cheap(E, R0, R) :-
    (   integer(E)
    ->  E > -1152921504606846976, E < 1152921504606846976,
        R is R0 - 1, R > 0
    ;   float(E)
    ->  R is R0 - 1, R > 0
    ;   atom(E)
    ->  R is R0 - 1, R > 0
    ;   compound(E),
        compound_name_arity(E, F, A),
        \+ risky(F),
        A > 0, A =< 3,
        \+ E = [_|_]
    ->  cheap_args(A, E, R0, R)
    ).

cheap_args(0, _, R, R) :- !.
cheap_args(I, E, R0, R) :-
    arg(I, E, X),
    cheap(X, R0, R1),
    I1 is I - 1,
    cheap_args(I1, E, R1, R).

risky(^).
risky(**).
risky(<<).
risky(>>).
risky(powm).
risky(roundtoward).
risky(rdiv).
risky(rational).
risky(rationalize).

eval_args(F, I, A, E, E1, Vs) :-
    (   I > A
    ->  Vs = []
    ;   arg(I, E, X),
        (   F == roundtoward, I == 2
        ->  Y = X
        ;   guest_eval(Y, X)
        ),
        arg(I, E1, Y),
        Vs = [Y|Vs1],
        I1 is I + 1,
        eval_args(F, I1, A, E, E1, Vs1)
    ).

check_op(F, Vs, E) :-
    bits_limit(Max),
    (   op_bits(F, Vs, Bits)
    ->  (   Bits > Max -> over_bits(E, Bits, Max) ; true )
    ;   true
    ).

%   op_bits(+Op, +Operands, -Bits): the bits the operation makes or
%   works on, for the operations that cost more than linear time or make
%   more bits than their operands have.
op_bits(*, [A, B], Bits) :- bits(A, BA), bits(B, BB), Bits is BA + BB.
op_bits(^, [A, B], Bits) :- power_bits(A, B, Bits).
op_bits(**, [A, B], Bits) :- power_bits(A, B, Bits).
op_bits(<<, [A, B], Bits) :- integer(B), bits(A, BA), Bits is BA + max(0, B).
op_bits(>>, [A, B], Bits) :- integer(B), bits(A, BA), Bits is BA + max(0, -B).
op_bits(powm, [B, E, M], Bits) :-
    bits(B, BB), bits(E, BE), bits(M, BM),
    Bits is max(BB, max(BM, BE * BM // 8192)).
op_bits(lcm, [A, B], Bits) :- bits(A, BA), bits(B, BB), Bits is BA + BB.
op_bits(F, Vs, Bits) :-
    memberchk(F, [/, //, div, mod, rem, gcd, rdiv, rational, rationalize,
                  +, -, min, max, cmpflags, truncate, integer]),
    max_bits(Vs, 0, Bits).

max_bits([], B, B).
max_bits([V|Vs], B0, B) :-
    bits(V, B1),
    B2 is max(B0, B1),
    max_bits(Vs, B2, B).

%   Bits of A^B for an integer exponent: |A| =< 1 makes no bits.
power_bits(A, B, Bits) :-
    (   integer(B), ( integer(A) ; rational(A) )
    ->  bits(A, BA),
        (   integer(A), abs(A) =< 1
        ->  Bits = BA
        ;   Bits is BA * max(1, abs(B))
        )
    ;   Bits = 0
    ).
int_operands(Culprit, Vs) :-
    bits_limit(Max),
    max_bits(Vs, 0, Bits),
    (   Bits > Max -> over_bits(Culprit, Bits, Max) ; true ).
