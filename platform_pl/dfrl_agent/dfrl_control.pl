/*  Send one control command to a running dFRL agent, through the node of
    its first stop:

        DFRL_TOKEN=T swipl -q platform_pl/dfrl_agent/dfrl_control.pl HOST PORT COMMAND.json

    The token comes from the environment variable DFRL_TOKEN (its first
    line; deleted once read). The older form with the token as an
    argument, HOST PORT TOKEN COMMAND.json, still works with a warning:
    an argument is visible to every user of the host (ps).

    COMMAND.json names the agent and holds one command
    (dfrl_console:dfrl_command/2):
      {"agent": "fed_qlearning", "join": {"host": "127.0.0.1", "port": 7006, "robot": "r6"}}
      {"agent": "fed_qlearning", "method": "median", "program": "/abs/median_method.pl",
       "nodes": [["127.0.0.1", 7001], ...]}       load the program on each node first
      {"agent": "fed_qlearning", "stop": true}
    It posts the platform event dfrl_control/4 with Args [Agent, Command]
    (contract C3); the agent applies it when it starts its next round.

    A long-lived console node (dfrl_console.pl) does the same with its
    `control` and `load_program` requests, without a process per command.
*/
:- use_module('../tartarus').
:- use_module('../messages', []).
:- use_module(dfrl_console, [dfrl_command/2]).
:- use_module('../secrets', [take_env_tokens/1, token_text_term/2]).
:- use_module(library(http/json), [json_read_dict/3]).
:- use_module(library(main)).

:- initialization(main, main).

main([Host, Port0, File]) :-
    take_env_tokens([Token|_]),
    !,
    main_([Host, Port0, Token, File]).
main([Host, Port0, Token0, File]) :-
    !,
    take_env_tokens(_),
    print_message(warning, dfrl(token_on_command_line)),
    token_text_term(Token0, Token),
    main_([Host, Port0, Token, File]).
main(_) :-
    format(user_error, "usage: DFRL_TOKEN=T swipl dfrl_control.pl HOST PORT COMMAND.json~n", []),
    halt(2).

main_([Host, Port0, Token, File]) :-
    atom_number(Port0, Port),
    catch(control(Host, Port, Token, File), E,
          ( print_message(error, E), halt(1) )).

control(Host, Port, Token, File) :-
    setup_call_cleanup(open(File, read, In, [encoding(utf8)]),
                       json_read_dict(In, C, []),
                       close(In)),
    (   get_dict(agent, C, Agent0)
    ->  atom_string(Agent, Agent0)
    ;   throw(error(existence_error(key, agent, C), _))
    ),
    dfrl_command(C, Command),
    load_first(C, Host, Port, Token),
    messages:agent_post(Host:Port, platform, dfrl_control, (Host, Port), [Agent, Command],
                        [tokens([Token])]),
    format("DFRL_CONTROL sent ~q to ~q~n", [Command, Agent]).

load_first(C, Host, Port, Token) :-
    (   get_dict(program, C, Program0)
    ->  atom_string(Program, Program0),
        (   get_dict(nodes, C, Nodes) -> true ; Nodes = [[Host, Port]] ),
        forall(member([H0, P], Nodes),
               ( atom_string(H, H0),
                 load_program_at(H:P, Program, [tokens([Token])]) ))
    ;   true
    ).
