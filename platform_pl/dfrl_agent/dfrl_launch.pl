/*  Launch a dFRL itinerary agent from a one-off console platform:

        swipl -q platform_pl/dfrl_agent/dfrl_launch.pl LAUNCH.json

    LAUNCH.json is a launch plan as dfrl_console:dfrl_launch_plan/4
    describes it (name, itinerary, method, rounds, rest_s, rounds_log,
    token, timeout_s). Starts a platform on an OS-chosen port (with the
    plan's token, else those of the environment variable DFRL_TOKEN, one
    per line, deleted once read), creates the agent and moves it to the
    first stop;
    exits 0 once the agent has left, 1 with the reason if it could not.

    A long-lived console node (dfrl_console.pl) does the same with its
    `launch` request, without a process per agent.
*/
:- use_module('../tartarus').
:- use_module(dfrl_console, [dfrl_launch/3, dfrl_launch_plan/4]).
:- use_module('../secrets', [take_env_tokens/1]).
:- use_module(library(http/json), [json_read_dict/3]).
:- use_module(library(main)).

:- initialization(main, main).

main([File]) :-
    !,
    catch(launch(File), E, ( print_message(error, E), halt(1) )).
main(_) :-
    format(user_error, "usage: swipl dfrl_launch.pl LAUNCH.json~n", []),
    halt(2).

launch(File) :-
    take_env_tokens(EnvTokens),
    setup_call_cleanup(open(File, read, In, [encoding(utf8)]),
                       json_read_dict(In, Plan, []),
                       close(In)),
    dfrl_launch_plan(Plan, _, _, Options),
    memberchk(tokens(Tokens0), Options),
    (   Tokens0 == [] -> Tokens = EnvTokens ; Tokens = Tokens0 ),
    node_start(localhost:0, Node, [tokens(Tokens)]),
    call_cleanup(dfrl_launch(Node, Plan, Result), node_stop(Node)),
    format("DFRL_AGENT ~w launched to ~w:~w~n",
           [Result.agent, Result.host, Result.port]).
