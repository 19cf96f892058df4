:- module(sandbox_agent_api,
          [ platform_module/1           % +Module
          ]).
:- use_module(sandbox_check, [code_refuse/2]).

:- multifile
    code_safety:agent_api/2,
    code_safety:moved_hook/2.

/** <module> The agent API, what sandboxed code may call of the platform

library(sandbox) extended for code that peers send (code_safety.pl):
output to the agent's own output, and the predicates of the platform's
modules that code_safety:agent_api/2 lists, under its conditions; any
other predicate of a platform module is refused. The platform's own
entries are here; an application adds its own clauses of
code_safety:agent_api/2.
*/

%   Output to the agent's output.
:- multifile sandbox:safe_primitive/1, sandbox:safe_meta/2.

sandbox:safe_primitive(system:nl).
sandbox:safe_primitive(system:flush_output).
sandbox:safe_primitive(system:print(_)).
sandbox:safe_primitive(system:write(_)).
sandbox:safe_primitive(system:writeq(_)).
sandbox:safe_primitive(system:write_canonical(_)).
sandbox:safe_primitive(system:tab(_)).

sandbox:safe_meta(system:format(Out, Format, Args), Calls) :-
    memberchk(Out, [user_output, user_error]),
    sandbox:format_calls(Format, Args, Calls).
sandbox:safe_meta(M:G, Calls) :-
    platform_module(M),
    (   code_safety:agent_api(M:G, Condition),
        call(Condition)
    ->  Calls = []
    ;   functor(G, F, A),
        (   code_safety:moved_hook(M:F/A, To)
        ->  code_refuse(moved_hook(M:F/A, To), _)
        ;   code_refuse(M:F/A, 'not part of the agent API')
        )
    ).

%   The platform's own modules: platform_pl/ and pybridge/. Nothing in
%   them is safe to a sandboxed caller unless agent_api/2 says so (the
%   sandbox's own analysis would, e.g., accept a predicate that asserts
%   into its own module, such as the one that sets the node's tokens).
:- dynamic platform_root/1.

:- prolog_load_context(directory, Dir),
   file_directory_name(Dir, Root),
   retractall(platform_root(_)),
   assertz(platform_root(Dir)),
   atom_concat(Root, '/pybridge', Py),
   assertz(platform_root(Py)).

platform_module(M) :-
    atom(M),
    module_property(M, file(File)),
    platform_root(Root),
    atom_concat(Root, '/', Prefix),
    sub_atom(File, 0, _, _, Prefix),
    !.

%   The platform's agent API (code_safety:agent_api/2 says what a clause
%   means).

code_safety:agent_api(tartarus:move_agent(A, _), self(A)).
code_safety:agent_api(tartarus:clone_agent(A, _, _), self(A)).
code_safety:agent_api(tartarus:post_agent(_, _, _), true).
code_safety:agent_api(tartarus:agent_post(_, _, _), true).
code_safety:agent_api(tartarus:add_payload(A, _), self(A)).
code_safety:agent_api(tartarus:remove_payload(A, _), self(A)).
code_safety:agent_api(tartarus:purge_agent(A), self(A)).
code_safety:agent_api(tartarus:execute_agent(A, _, _), self(A)).
code_safety:agent_api(tartarus:execute_agent(A, _, _, _), self(A)).
code_safety:agent_api(tartarus:get_tartarus_details(_, _), true).
code_safety:agent_api(tartarus:isexist_agent(_, _, _), true).
code_safety:agent_api(tartarus:list_agents, true).
code_safety:agent_api(tartarus:list_agents(_), true).
code_safety:agent_api(tartarus:list_agent, true).
code_safety:agent_api(tartarus:list_agent(_), true).
code_safety:agent_api(tartarus:agent_hop_times(_, _), true).
code_safety:agent_api(tartarus:agent_hop_statistics(_, _), true).
code_safety:agent_api(migration:agent_move(A, _, _), self(A)).
code_safety:agent_api(migration:agent_clone(A, _, _, _), self(A)).
code_safety:agent_api(messages:agent_post(_, _, _, _, _), true).
code_safety:agent_api(messages:agent_post(_, _, _, _, _, _), true).
code_safety:agent_api(messages:remote_agents(_, _, _), true).
%   agents.pl re-exports these (agent_execution.pl, agent_registry.pl and
%   agent_code.pl define them): the sandbox finds a predicate where it is
%   defined.
code_safety:agent_api(agent_execution:current_agent(_), true).
code_safety:agent_api(agent_registry:agent_property(_, A, P),
                      ( nonvar(P), agent_may_see(A, P) )).
code_safety:agent_api(agent_code:agent_add_payload(_, A, _), self(A)).
code_safety:agent_api(agent_code:agent_remove_payload(_, A, _), self(A)).
code_safety:agent_api(agent_code:agent_add_facts(_, A, _), self(A)).
code_safety:agent_api(agent_registry:agent_exists(_, _), true).
code_safety:agent_api(agent_registry:agent_list(_, _), true).
code_safety:agent_api(agent_registry:agent_hop_times(_, _, _), true).
%   node.pl re-exports these (node_registry.pl defines them): the
%   sandbox finds a predicate where it is defined.
code_safety:agent_api(node_registry:current_node(_), true).
code_safety:agent_api(node_registry:node_property(_, P), ( nonvar(P), public_node_property(P) )).
code_safety:agent_api(robot_resources:get_robot_table(_, _, _), true).
code_safety:agent_api(robot_resources:get_robot_tables(_, _, _, _), true).
code_safety:agent_api(robot_resources:set_robot_table(_, _, _), true).
code_safety:agent_api(robot_resources:get_robot_params(_, _, _), true).
code_safety:agent_api(robot_resources:set_robot_params(_, _, _), true).
code_safety:agent_api(robot_resources:read_robot_table(_, _, _), true).
code_safety:agent_api(robot_resources:read_robot_tables(_, _, _, _), true).
code_safety:agent_api(robot_resources:write_robot_table(_, _, _), true).
code_safety:agent_api(robot_resources:read_robot_params(_, _, _), true).
code_safety:agent_api(robot_resources:write_robot_params(_, _, _), true).
code_safety:agent_api(robot_resources:hosted_robot(_, _), true).

%   An agent sees its own properties but its tokens; of other agents,
%   what list_agents/0 shows (never their module, payload or tokens).
agent_may_see(A, P) :-
    P \= tokens(_),
    (   self(A)
    ->  true
    ;   public_agent_property(P)
    ).

public_agent_property(handler(_)).
public_agent_property(kind(_)).
public_agent_property(status(_)).
public_agent_property(hops(_)).

public_node_property(address(_)).
public_node_property(link(_)).
public_node_property(id(_)).
public_node_property(bind(_)).

self(A) :-
    nonvar(A),
    catch(b_getval(code_safety_self, Self), _, fail),
    A == Self.
