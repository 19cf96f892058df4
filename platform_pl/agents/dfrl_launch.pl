/*  Launch a dFRL itinerary agent from a console platform:

        swipl -q platform_pl/agents/dfrl_launch.pl LAUNCH.json

    LAUNCH.json:
      { "name": "fed_q",                       agent name
        "itinerary": [{"host": "127.0.0.1", "port": 7001, "robot": "r1"}, ...],
        "method": "average" | "max" | "visit_average" | injected name,
        "rounds": 16,                          round budget
        "rest_s": 0.0,                         rest at the first stop between rounds
        "rounds_log": "/abs/rounds.log",       one round(...) fact per round
        "token": 1111,                         token of the robot nodes
        "timeout_s": 3600 }                    how long a table read/write may wait

    Starts a console platform on an OS-chosen port, creates the agent and
    moves it to the first stop; exits 0 once the agent has left, 1 with the
    reason if it could not.
*/
:- use_module('../tartarus').
:- use_module(dfrl_agent).
:- use_module(library(http/json)).
:- use_module(library(main)).

:- initialization(main, main).

main([File]) :-
    !,
    catch(launch(File), E, ( print_message(error, E), halt(1) )).
main(_) :-
    format(user_error, "usage: swipl dfrl_launch.pl LAUNCH.json~n", []),
    halt(2).

launch(File) :-
    setup_call_cleanup(open(File, read, In), json_read_dict(In, C, [value_string_as(atom)]), close(In)),
    get_dict(itinerary, C, Stops0),
    maplist(stop_term, Stops0, Stops),
    dict_default(C, rounds, 1, Rounds),
    dict_default(C, rest_s, 0.0, Rest0), Rest is float(Rest0),
    dict_default(C, rounds_log, 'rounds.log', Log),
    dict_default(C, timeout_s, 3600, Timeout),
    dict_default(C, method, average, Method),
    dict_default(C, name, dfrl, Name),
    (   get_dict(token, C, Token) -> Tokens = [Token], NodeOpts = [token(Token)]
    ;   Tokens = [], NodeOpts = []
    ),
    node_start(localhost:0, Node, NodeOpts),
    dfrl_create(Node, Name, plan(Stops, Rounds, Rest, Log, Timeout),
                [method(Method), tokens(Tokens)]),
    Stops = [stop(H, P, _)|_],
    move_agent(Name, (H, P)),
    format("DFRL_AGENT ~w launched to ~w:~w~n", [Name, H, P]),
    node_stop(Node).

stop_term(D, stop(H, P, R)) :-
    get_dict(host, D, H),
    get_dict(port, D, P),
    get_dict(robot, D, R).

dict_default(D, K, Def, V) :-
    (   get_dict(K, D, V0) -> V = V0 ; V = Def ).
