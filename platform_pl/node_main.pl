/*  Run one platform node as a program:

        swipl platform_pl/node_main.pl [--host H] [--port P] [--token T]...
                                       [--consult FILE]... [--interactive]

    Prints "dfrl node listening on H:P" once it listens, then serves until
    killed (or, with --interactive, until the toplevel ends). Numeric tokens
    are read as integers, as Tartarus tokens are.
*/
:- use_module(tartarus).
:- use_module(library(main)).
:- use_module(library(optparse), []).

:- initialization(main, main).

main(Argv) :-
    parse(Argv, opts(localhost, 0, [], [], false), opts(Host, Port, Tokens, Files, Interactive)),
    (   Tokens == []
    ->  node_start(Host:Port, Node, [default(true)])
    ;   node_start(Host:Port, Node, [tokens(Tokens), default(true)])
    ),
    forall(member(F, Files), load_program(F)),
    node_property(Node, address(H:P)),
    format("dfrl node listening on ~w:~w~n", [H, P]),
    flush_output,
    (   Interactive == true
    ->  prolog
    ;   thread_get_message(_)          % serve until killed
    ).

parse([], O, O).
parse(['--host', H|T], opts(_, P, K, F, I), O) :- !, parse(T, opts(H, P, K, F, I), O).
parse(['--port', P0|T], opts(H, _, K, F, I), O) :- !,
    atom_number(P0, P), parse(T, opts(H, P, K, F, I), O).
parse(['--token', T0|T], opts(H, P, K, F, I), O) :- !,
    (   atom_number(T0, Tok) -> true ; Tok = T0 ),
    append(K, [Tok], K1), parse(T, opts(H, P, K1, F, I), O).
parse(['--consult', File|T], opts(H, P, K, F, I), O) :- !,
    append(F, [File], F1), parse(T, opts(H, P, K, F1, I), O).
parse(['--interactive'|T], opts(H, P, K, F, _), O) :- !, parse(T, opts(H, P, K, F, true), O).
parse([X|_], _, _) :-
    format(user_error, "Unknown argument: ~w~n", [X]),
    halt(2).
