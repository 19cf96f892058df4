/*  Send a control command to a running dFRL agent, through the node of its
    first stop:

        swipl -q platform_pl/agents/dfrl_control.pl HOST PORT TOKEN COMMAND.json

    COMMAND.json is one of
      {"join":   {"host": "127.0.0.1", "port": 7006, "robot": "r6"}}
      {"method": "median", "program": "/abs/median_method.pl",
       "nodes": [["127.0.0.1", 7001], ...]}        load program on each node first
      {"stop": true}
    The agent applies it when it starts its next round.
*/
:- use_module('../tartarus').
:- use_module(library(http/json)).
:- use_module(library(main)).

:- initialization(main, main).

main([Host, Port0, Token0, File]) :-
    !,
    atom_number(Port0, Port),
    (   atom_number(Token0, Token) -> true ; Token = Token0 ),
    catch(control(Host, Port, Token, File), E,
          ( print_message(error, E), halt(1) )).
main(_) :-
    format(user_error, "usage: swipl dfrl_control.pl HOST PORT TOKEN COMMAND.json~n", []),
    halt(2).

control(Host, Port, Token, File) :-
    setup_call_cleanup(open(File, read, In), json_read_dict(In, C, [value_string_as(atom)]), close(In)),
    command(C, Host, Port, Token, Command),
    agent_post(Host:Port, platform, dfrl_control, (Host, Port), [Command]),
    format("DFRL_CONTROL sent ~q~n", [Command]).

command(C, _, _, _, join(stop(H, P, R))) :-
    get_dict(join, C, J), !,
    get_dict(host, J, H), get_dict(port, J, P), get_dict(robot, J, R).
command(C, Host, Port, Token, method(M)) :-
    get_dict(method, C, M), !,
    (   get_dict(program, C, Program)
    ->  (   get_dict(nodes, C, Nodes) -> true ; Nodes = [[Host, Port]] ),
        forall(member([H, P], Nodes),
               load_program_at(H:P, Program, [tokens([Token])]))
    ;   true
    ).
command(C, _, _, _, stop) :-
    get_dict(stop, C, true), !.
command(C, _, _, _, _) :-
    throw(error(domain_error(dfrl_command, C), _)).
