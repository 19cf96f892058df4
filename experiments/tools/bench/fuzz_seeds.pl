/*  The valid binary frames that `dfrl bench fuzz` (fuzz.py) mutates.

    swipl fuzz_seeds.pl
        Prints one line per seed: its name, a space, and the hex of the
        body fast_term_serialized/2 makes of it (what an authenticated
        peer sends as a binary frame). Between them the seeds use every
        opcode the platform's binary frames carry: requests the node
        serves (ping, agents, migration_status/1), a transfer/6 shaped as
        a migration's (whose record the node refuses: no such migration),
        and unknown requests holding integers of every width, floats, a
        packed vector, strings and atoms (wide ones too), variables,
        compounds of arity 0, dicts (as the dFRL agent's state), a long
        list, nesting 60 deep.
*/
:- initialization(main, main).

main :-
    forall(seed(Name, Term),
           ( fast_term_serialized(Term, Bytes),
             string_codes(Bytes, Codes),
             format("~w ", [Name]),
             forall(member(C, Codes), format("~|~`0t~16r~2+", [C])),
             nl )).

seed(ping, ping).
seed(agents, agents).
seed(status, migration_status('mig-7f3a')).
seed(transfer, transfer('mig-7f3a', move, node('127.0.0.1', 40001, [id(peer)]),
                        1764763200.25,
                        agent_record(fuzzer, [token(4243)], "handler(_, _) :- true.",
                                     payload([table-fts(Packed), visits-[3, 0, 7]])),
                        1)) :-
    floats(100, Fs),
    fast_term_serialized(Fs, Packed).
%   a message to an agent, binary since agent_post/5 sends binary frames on an authenticated
%   connection: a tree clone's table handed to its parent (a packed vector)
seed(post, post(platform, dfrl_tree_msg, link('mig-7f3a'),
                [msg(key(fr, 3), up(c1, [r2-fts(Packed)]))])) :-
    floats(100, Fs),
    fast_term_serialized(Fs, Packed).
seed(numbers, fuzz(numbers, [0, 1, -1, 127, 128, -129, 65535, 72057594037927935,
                             72057594037927936, -72057594037927937, Big, NegBig],
                   [1.5, -0.0, 1.0e300, 5.0e-324])) :-
    Big is 2^70 + 3,
    NegBig is -(2^130).
seed(text, fuzz(text, "plain string", "wide ωστε", 'wide atom →', '', "",
                f(), '[]'(x), [a|b], 'quoted atom''s')).
seed(variables, fuzz(vars, g(X, Y, X, _Z, Y), [X, Y])).
seed(dicts, fuzz(dicts, _{acc:packed("x"), round:3, robots:[r1, r2]}, t{k:_{7:v, 'ω':w}})).
seed(long_list, fuzz(list, Fs)) :-
    floats(300, Fs).
seed(nested, fuzz(nested, Deep, DeepList)) :-
    nest(60, f, x, Deep),
    nest_list(60, [y], DeepList).

floats(N, Fs) :-
    findall(F, ( between(1, N, I), F is I * 0.37 - 11.0 ), Fs).

nest(0, _, T, T) :- !.
nest(N, F, T0, T) :-
    T1 =.. [F, T0],
    N1 is N - 1,
    nest(N1, F, T1, T).

nest_list(0, T, T) :- !.
nest_list(N, T0, T) :-
    N1 is N - 1,
    nest_list(N1, [T0], T).
