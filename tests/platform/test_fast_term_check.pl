/*  plunit tests of fast_term_check.pl: everything fast_term_serialized/2
    writes for plain terms is accepted, in C and in the Prolog fallback;
    mutated bytes are judged alike by both, and whatever is accepted
    decodes to a term that serialises back to the very same bytes (so the
    decoder only ever sees what it writes itself).
    Run: swipl -g run_tests -t halt test_fast_term_check.pl
*/
:- use_module('../../platform_pl/fast_term_check').
:- use_module(library(plunit)).
:- use_module(library(random)).
:- use_module(library(lists)).
:- use_module(library(memfile)).

:- begin_tests(fast_term_check).

%   Terms of every kind the check accepts.
sample(T) :-
    X is 2^63, Y is -(2^63) - 1, Z is 2^200 + 7,
    wide_atom(WA), wide_string(WS),
    dict_create(WD, _, [WA-w, 7-seven]),
    length(Floats, 50), maplist(=(1.5e-300), Floats),
    fast_term_serialized(Floats, Packed),
    member(T, [ a, [], 0, -1, 127, 128, -128, -129, 72057594037927935,
                -72057594037927936, 72057594037927936, 9223372036854775807,
                -9223372036854775808, X, Y, Z, 1.5, -0.0, nan_free,
                "", "abc", "ÿé", WS, WA, f(WA), foo(), '[]'(x), f('[]'), dict,
                f(_), f(A, A, _B), g(_C, D, D), _, [1, 2.0, "s", b|t],
                transfer(agent(id, [token(1)], "code"), payload(fts(Packed))),
                f(X, Y, Z), [[[[a]]]], f(f(f(f(f(f(x)))))), '\x0\'(1),
                _{a:1, b:"x", c:[1.5]}, t{k:_{z:1}, 3:f(_)}, WD, f(_{})
              ]).

wide_atom(A) :- atom_codes(A, [0x3b1, 0x3b2, 0x1F600]).
wide_string(S) :- string_codes(S, [0x61, 0x3b1, 0x10FFFF]).

%   The Prolog walk, also where the C library is loaded.
prolog_result(Bytes, Depth, R) :-
    fast_term_check:prolog_check(Bytes, Depth, R).

test(serialised_terms_accepted, [forall(sample(T))]) :-
    fast_term_serialized(T, Bytes),
    fast_term_bytes_check(Bytes, 100, R1),
    prolog_result(Bytes, 100, R2),
    assertion(R1 == true),
    assertion(R2 == true).

test(dict_keys) :-
    fast_term_serialized(_{a:1, b:2}, B),
    string_codes(B, C0),
    once(append(Pre, [11, 1, 0'b|Post], C0)),   % key b renamed a: a duplicate
    append(Pre, [11, 1, 0'a|Post], C1),
    string_codes(Dup, C1),
    fast_term_bytes_check(Dup, 10, R1),
    prolog_result(Dup, 10, R2),
    assertion(R1 == duplicate_key),
    assertion(R2 == duplicate_key).

test(refused) :-
    forall(member(Bad-Why,
                  [ ""-too_short, "r"-too_short,
                    "z\x0a\"-bad_opcode,                % the dict functor alone
                    "r\x1\\x0\\x1\"-bad_varint,          % a variable without its number
                    "r\x2\\x3\\xe\\x1\"-float_past_end,
                    "r\x1\\x2\\x9\"-cells_mismatch,      % [] announced as 2 cells
                    "b\x2\\x0\\x1\\x1\\x1\"-bad_variable, % variable 1 of 1
                    "r\x3\\x3\\x6\\x1\\x41\"-bad_string  % not 'B' nor 'W'
                  ]),
           ( fast_term_bytes_check(Bad, 10, R),
             prolog_result(Bad, 10, R2),
             assertion(R \== true), assertion(R2 \== true),
             ( R == Why -> true ; format(user_error, "~q: ~q (~q)~n", [Bad, R, Why]) ) )).

test(depth) :-
    numlist(1, 300, L),
    foldl([_, T0, f(T0)]>>true, L, x, Deep),
    fast_term_serialized(Deep, Bytes),
    fast_term_bytes_check(Bytes, 300, true),
    fast_term_bytes_check(Bytes, 299, too_deep),
    prolog_result(Bytes, 299, too_deep),
    numlist(1, 5000, Long),
    fast_term_serialized([Long], LB),           % a long list is one level deep
    fast_term_bytes_check(LB, 2, true),
    fast_term_bytes_check(LB, 1, too_deep).

test(not_bytes) :-
    fast_term_bytes_check("r\x100\", 5, not_bytes).

test(decode_refuses, [throws(error(domain_error(fast_term_bytes, cells_mismatch), _))]) :-
    fast_term_decode("r\x1\\x2\\x9\", _, []).

%   fast_term_read/5 on a stream of Bytes then "rest", in C and in Prolog.
read_from(Bytes, Len, Native, Term, Result, Rest) :-
    setup_call_cleanup(
        new_memory_file(MF),
        ( setup_call_cleanup(open_memory_file(MF, write, W, [encoding(octet)]),
                             ( write(W, Bytes), write(W, "rest") ), close(W)),
          setup_call_cleanup(
              open_memory_file(MF, read, In, [encoding(octet)]),
              ( set_stream(In, record_position(false)),
                with_native(Native, fast_term_read(In, Len, 50, Term, Result)),
                read_string(In, _, Rest) ),
              close(In)) ),
        free_memory_file(MF)).

with_native(true, Goal) :- call(Goal).
with_native(false, Goal) :-
    setup_call_cleanup(
        ( retract(fast_term_check:native(Was)), assertz(fast_term_check:native(false)) ),
        Goal,
        ( retractall(fast_term_check:native(_)), assertz(fast_term_check:native(Was)) )).

test(stream_read, [forall(member(Native, [true, false]))]) :-
    T = f("abc", [1.5, 2.5], _X, 'ωx'),
    fast_term_serialized(T, B),
    string_length(B, Len),
    read_from(B, Len, Native, T1, R1, Rest1),
    assertion(R1 == true), assertion(T1 =@= T), assertion(Rest1 == "rest"),
    Short is Len - 2,                           % the header claims 2 bytes less
    read_from(B, Short, Native, _, R2, _),
    assertion(R2 == code_past_end),
    Long is Len + 10,                           % the stream ends first
    read_from(B, Long, Native, _, R3, _),
    assertion(R3 == truncated).

%   Mutations of every sample: C and Prolog agree on accepting, and what is
%   accepted decodes and serialises back to the same bytes. Seeded; the
%   seed is printed when a case fails.
test(mutations_judged_alike) :-
    Seed = 20261203,
    set_random(seed(Seed)),
    findall(B, ( sample(T), fast_term_serialized(T, B) ), Bs),
    forall(between(1, 3000, I),
           ( random_member(B0, Bs),
             string_codes(B0, C0),
             mutate(C0, C1),
             string_codes(M, C1),
             fast_term_bytes_check(M, 50, R1),
             prolog_result(M, 50, R2),
             (   accepted(R1, A), accepted(R2, A)
             ->  true
             ;   format(user_error, "seed ~w case ~w: ~q C ~q Prolog ~q~n", [Seed, I, C1, R1, R2]),
                 fail
             ),
             (   R1 == true
             ->  fast_term_serialized(Term, M),
                 fast_term_serialized(Term, Again),
                 (   Again == M
                 ->  true
                 ;   sub_term(D, Term), is_dict(D)   % keys sorted here: same term
                 ->  fast_term_serialized(Term2, Again),
                     assertion(Term2 =@= Term)
                 ;   assertion(Again == M)
                 )
             ;   true
             ) )).

accepted(R, A) :- ( R == true -> A = yes ; A = no ).

mutate(C0, C) :-
    length(C0, N),
    random_between(0, 5, K),
    (   N =:= 0 -> C = [1]
    ;   K =:= 0 -> random_between(1, N, I), nth1(I, C0, X, Rest),   % flip a bit
                   random_between(0, 7, Bit), Y is X xor (1 << Bit), nth1(I, C, Y, Rest)
    ;   K =:= 1 -> random_between(1, N, I), nth1(I, C0, _, Rest),   % change a byte
                   random_between(0, 255, Y), nth1(I, C, Y, Rest)
    ;   K =:= 2 -> random_between(0, N, L), length(C, L), append(C, _, C0)  % truncate
    ;   K =:= 3 -> random_between(0, N, I), length(P, I), append(P, S, C0), % insert
                   random_between(0, 255, Y), append(P, [Y|S], C)
    ;   K =:= 4 -> random_between(1, N, I), nth1(I, C0, _, C)       % delete
    ;   random_between(1, N, I), nth1(I, C0, _, Rest),              % a small number
        random_member(Y, [0, 1, 2, 8, 9, 13, 127, 128, 255]), nth1(I, C, Y, Rest)
    ).

:- end_tests(fast_term_check).
