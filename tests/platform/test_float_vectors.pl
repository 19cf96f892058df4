/*  plunit tests of float_vectors.pl: packed vectors give the bits lists
    give, in C and in the Prolog fallback; malformed ones are refused, not
    decoded.
    Run: swipl -g run_tests -t halt test_float_vectors.pl
*/
:- use_module('../../platform_pl/float_vectors').
:- use_module(library(plunit)).
:- use_module(library(random)).

:- begin_tests(float_vectors).

%   N floats of every kind a table may hold: both signs, large and small
%   magnitudes, subnormals, zeros of both signs. Seeded.
floats(Seed, N, Fs) :-
    set_random(seed(Seed)),
    length(Fs, N),
    maplist(a_float, Fs).

a_float(F) :-
    random_between(0, 9, K),
    random(U),
    (   K =:= 0 -> F = -0.0
    ;   K =:= 1 -> F is U * 1.0e-310              % subnormal
    ;   K =:= 2 -> F is -U * 1.0e150
    ;   K =:= 3 -> F is U * 1.0e12
    ;   F is (U - 0.5) * 200.0
    ).

%   Run Goal with the C library switched off (the Prolog fallback).
without_native(Goal) :-
    setup_call_cleanup(
        ( retract(float_vectors:native(true)), assertz(float_vectors:native(false)) ),
        Goal,
        ( retract(float_vectors:native(false)), assertz(float_vectors:native(true)) )).

%   The operations, each on packed vectors and on lists.
op(add,   P, Q, R) :- vector_add(P, Q, R).
op(mul,   P, Q, R) :- vector_mul(P, Q, R).
op(max,   P, Q, R) :- vector_max(P, Q, R).
op(div7,  P, _, R) :- vector_divide(P, 7, R).
op(times, P, _, R) :- vector_times(P, 1234, R).
op(axpy,  P, Q, R) :- vector_add_scaled(P, 3, Q, R).
op(wmean, P, Q, R) :- vector_weighted_mean(P, Q, P, 5, R).

list_op(add,   X, Y, Z) :- add_lists(X, Y, Z).
list_op(mul,   X, Y, Z) :- mul_lists(X, Y, Z).
list_op(max,   X, Y, Z) :- max_lists(X, Y, Z).
list_op(div7,  X, _, Z) :- scale_list(X, 7, Z).
list_op(times, X, _, Z) :- times_list(X, 1234, Z).
list_op(axpy,  X, Y, Z) :- add_scaled(X, 3, Y, Z).
list_op(wmean, X, Y, Z) :- weighted_mean(X, Y, X, 5, Z).

test(native_built, [true(B == true)]) :-
    float_vectors_native(B).

%   Every operation on packed vectors gives, bit for bit, the packed form
%   of what is/2 gives on the lists: with the C library and without.
test(same_bits_as_is, [forall(member(Op, [add, mul, max, div7, times, axpy, wmean]))]) :-
    floats(1, 3000, Xs), floats(2, 3000, Ys0),
    (   Op == wmean                     % weights: visit counts 0..4
    ->  maplist([Y, C]>>(C is float(truncate(abs(Y)) mod 5)), Ys0, Ys)
    ;   Ys = Ys0
    ),
    vector_packed(Xs, P), vector_packed(Ys, Q),
    list_op(Op, Xs, Ys, Zs),
    vector_packed(Zs, Want),
    op(Op, P, Q, Native),
    without_native(op(Op, P, Q, Fallback)),
    assertion(Native == Want),
    assertion(Fallback == Want),
    % control: the comparison tells operations apart
    (   Op \== add
    ->  op(add, P, Q, Other), assertion(Other \== Want)
    ;   true
    ).

%   Lists in, lists out; a list and a packed vector: a list.
test(lists_stay_lists) :-
    floats(3, 100, Xs), floats(4, 100, Ys),
    vector_packed(Ys, Q),
    vector_add(Xs, Ys, Z1),
    vector_add(Xs, Q, Z2),
    add_lists(Xs, Ys, Want),
    assertion(Z1 == Want),
    assertion(Z2 == Want).

test(round_trip) :-
    floats(5, 500, Xs),
    vector_packed(Xs, P),
    vector_floats(P, Back),
    assertion(Back == Xs),
    vector_length(P, N),
    assertion(N == 500),
    without_native(vector_length(P, N2)),
    assertion(N2 == 500).

test(empty) :-
    vector_packed([], P),
    vector_add(P, P, S),
    vector_floats(S, L),
    assertion(L == []),
    vector_length(P, N),
    assertion(N == 0).

test(lengths_differ, [fail]) :-
    vector_packed([1.0, 2.0], P), vector_packed([1.0], Q),
    vector_add(P, Q, _).

test(lengths_differ_fallback, [fail]) :-
    vector_packed([1.0, 2.0], P), vector_packed([1.0], Q),
    without_native(vector_add(P, Q, _)).

%   A sum that overflows raises what is/2 raises on the lists.
test(overflow_raises, [error(evaluation_error(float_overflow))]) :-
    vector_packed([1.0e308], P),
    vector_add(P, P, _).

test(not_a_float, [error(type_error(float, 1))]) :-
    vector_packed([1.0, 1], _).

%   Malformed packed vectors (as a peer might send them) are refused
%   before fast_term_serialized/2, which trusts its input, sees them.
bad(Name, String) :-
    vector_packed([1.5, 2.5, 3.5], fts(Good)),
    string_codes(Good, Codes),
    once(bad_codes(Name, Codes, BadCodes)),
    string_codes(String, BadCodes).

bad_codes(tag, Codes, Bad) :-             % an element's tag says integer
    nth0(I, Codes, 14, _), !,
    nth0(I, Codes, _, Rest), nth0(I, Bad, 9, Rest).
bad_codes(truncated, Codes, Bad) :-
    append(Bad, [_, _], Codes).
bad_codes(trailer, Codes, Bad) :-
    append(Front, [_], Codes), append(Front, [0], Bad).
bad_codes(count, [H, _|T], [H, 0'\x15\|T]).   % varint(10N+1) of another N
bad_codes(garbage, _, `hello world`).

test(malformed_refused, [forall(member(Name, [tag, truncated, trailer, count, garbage]))]) :-
    bad(Name, S),
    catch(vector_floats(fts(S), _), E, true),
    assertion(nonvar(E)),
    assertion(E = error(domain_error(fts_float_list, _), _)),
    catch(without_native(vector_floats(fts(S), _)), E2, true),
    assertion(E2 = error(domain_error(fts_float_list, _), _)),
    catch(vector_add(fts(S), fts(S), _), E3, true),
    assertion(E3 = error(domain_error(fts_float_list, _), _)).

%   A count so large that 10 x count wraps round 64 bits to the body's
%   real length: refused before a byte past the string is read.
test(count_that_wraps_refused, [error(domain_error(fts_float_list, _))]) :-
    N is (34 + 2^64) // 10,
    V2 is 6 * N,
    varint_codes(35, H1),                      % 10N+1 modulo 2^64
    varint_codes(V2, H2),
    Elem = [8, 14, 0, 0, 0, 0, 0, 0, 0xf0, 0x3f],
    append([Elem, Elem, Elem, [8, 14, 0, 0], [9]], Body),
    append([[114], H1, H2, Body], Codes),
    string_codes(S, Codes),
    vector_length(fts(S), _).

varint_codes(V, Codes) :-
    varint_groups(V, [], Groups),
    append(Init, [Last], Groups),
    maplist([G, C]>>(C is G \/ 0x80), Init, Hi),
    append(Hi, [Last], Codes).

varint_groups(V, Acc, Groups) :-
    G is V /\ 0x7f,
    V1 is V >> 7,
    (   V1 =:= 0
    ->  Groups = [G|Acc]
    ;   varint_groups(V1, [G|Acc], Groups)
    ).

%   Control: the good vector the bad ones are made from is taken.
test(unmodified_taken) :-
    vector_packed([1.5, 2.5, 3.5], P),
    vector_floats(P, L),
    assertion(L == [1.5, 2.5, 3.5]).

:- end_tests(float_vectors).
